"""The visible wavelengths the material tests evaluate on."""
from __future__ import annotations

import numpy as np

VISIBLE = np.linspace(360.0, 830.0, 471)  # 1 nm steps, both ends of Mitsuba's range included

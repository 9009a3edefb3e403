"""Stacks (thinfilm_mi/materials/stack.py): the numpy ``Stack`` API naming its arguments,
and ``layers`` strings that quote a file path."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi as tf  # noqa: E402
from thinfilm_mi.errors import ThinFilmError  # noqa: E402
from thinfilm_mi.materials.stack import MAX_FILMS  # noqa: E402


def test_numpy_stack_errors_name_the_argument():
    with pytest.raises(ThinFilmError, match=r"^layers\[2\] material: .*1e\+30"):
        tf.Stack([(1.5, 10), (1.4, 10), ("1e30", 5)])
    with pytest.raises(ThinFilmError, match=r"^substrate: unknown material 'Auu'"):
        tf.Stack(substrate="Auu")
    with pytest.raises(ThinFilmError, match=r"^ambient: .*nan"):
        tf.Stack(ambient=float("nan"))
    with pytest.raises(ThinFilmError, match=r"^layers: 1001 films given"):
        tf.Stack([(1.5, 1.0)] * (MAX_FILMS + 1))





def test_layers_quote_a_path_with_a_semicolon_and_a_space(tmp_path):
    plain = tmp_path / "glass.csv"
    plain.write_text("360,1.7,0\n830,1.6,0\n")
    odd = tmp_path / "my films" / "a;b.csv"
    odd.parent.mkdir()
    odd.write_text(plain.read_text())
    text = tf.materials.stack.format_layers([(str(odd), 120.0), ("SiO2", 80.25)])
    assert text == f'"{odd}" 120; SiO2 80.25'
    assert tf.parse_layers(text) == [(str(odd), 120.0), ("SiO2", 80.25)]
    assert tf.parse_layers(f"'{odd}' 120") == [(str(odd), 120.0)]
    wl = np.linspace(360.0, 830.0, 11)
    R = tf.Stack(layers=text, substrate=1.5).rt(wavelength=wl, theta=0.3).R
    np.testing.assert_array_equal(R, tf.Stack(layers=f"{plain} 120; SiO2 80.25", substrate=1.5)
                                  .rt(wavelength=wl, theta=0.3).R)
    with pytest.raises(tf.ThinFilmError, match=r"thickness must be a number of nm, got 'films/a' .*goes in quotes"):
        tf.parse_layers(f"{odd} 120")

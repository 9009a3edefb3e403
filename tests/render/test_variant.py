"""Variants (thinfilm_mi/render/variant.py): the thin-film plugins refuse the variants
they do not support, clearly."""
import mitsuba as mi
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins)


@pytest.mark.parametrize("variant_name", ["llvm_ad_mono_polarized"])
def test_unsupported_variants_raise_clearly(variant_name):
    mi.set_variant(variant_name)
    try:
        for plugin in ("thinfilm_conductor", "thinfilm_dielectric"):
            with pytest.raises(Exception, match="not supported"):
                mi.load_dict({"type": plugin, "layers": "1.46 100"})
    finally:
        mi.set_variant("llvm_ad_spectral")

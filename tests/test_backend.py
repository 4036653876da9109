import pytest

import mitsuba_eventfield as ef


def test_auto_choice_is_vectorised_mono_or_rgb():
    assert ef.choose_variant() in ("llvm_ad_mono", "cuda_ad_mono")
    assert ef.choose_variant(color=True).endswith("_ad_rgb")
    assert ef.choose_variant("llvm") == "llvm_ad_mono"


@pytest.mark.parametrize("variant, message", [("scalar_rgb", "90x slower"), ("llvm_ad_foo", "not compiled")])
def test_bad_variants_are_refused(variant, message):
    with pytest.raises(ef.EventFieldError, match=message):
        ef.choose_variant(variant)


def test_llvm_library_is_at_least_16():
    import os
    import re
    path = os.environ.get("DRJIT_LIBLLVM_PATH", "")
    m = re.search(r"LLVM[-.]?(\d+)", os.path.basename(path))
    assert m and int(m.group(1)) >= 16, path

"""lvcore._exports: the deprecation shims for moved names and renamed keywords."""
from __future__ import annotations

import types
import warnings

import pytest

from lvcore._exports import moved_names, renamed_keywords


def test_a_moved_name_forwards_to_its_new_home_with_a_deprecation_warning():
    old = types.ModuleType("old_home")
    old.__getattr__ = moved_names("old_home", {"KPA": "lvcore.units:KPA_PER_MMHG"})
    with pytest.warns(DeprecationWarning, match=r"old_home\.KPA is deprecated; use lvcore\.units\.KPA_PER_MMHG"):
        from lvcore.units import KPA_PER_MMHG

        assert old.__getattr__("KPA") == KPA_PER_MMHG
    with pytest.raises(AttributeError, match="has no attribute 'other'"):
        old.__getattr__("other")


def test_a_renamed_keyword_is_accepted_under_its_old_name_with_a_deprecation_warning():
    @renamed_keywords(edp="edp_mmhg")
    def f(x, *, edp_mmhg=8.0):
        """Docstring kept."""
        return x, edp_mmhg

    assert f.__doc__ == "Docstring kept." and f.__name__ == "f"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert f(1, edp_mmhg=10.0) == (1, 10.0) and f(1) == (1, 8.0)  # the new name: no warning
    with pytest.warns(DeprecationWarning, match=r"f\(edp=\.\.\.\) is deprecated; use edp_mmhg="):
        assert f(1, edp=12.0) == (1, 12.0)
    with pytest.raises(TypeError, match="got 'edp_mmhg' and its old name 'edp'"):
        f(1, edp=12.0, edp_mmhg=10.0)

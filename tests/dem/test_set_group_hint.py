"""``--set contact_dashpot_ratio=...`` was answered "did you mean contact_gaps": the key exists
only inside the ``damping`` group, and the hint must name the dotted key."""

from __future__ import annotations

import pytest

from sim_backend.dem.spec import ChainFileError, apply_settings


def test_an_undotted_group_key_suggests_the_dotted_name() -> None:
    with pytest.raises(ChainFileError, match=r"damping\.contact_dashpot_ratio") as info:
        apply_settings({}, ["contact_dashpot_ratio=0.01"])
    assert "contact_gaps" not in str(info.value) and "\n" not in str(info.value)


def test_dotted_and_top_level_keys_still_apply() -> None:
    out = apply_settings({"damping": {"bending_mode_ratio": 0.002}},
                         ["damping.contact_dashpot_ratio=0.01", "n_modes=4"])  # fmt: skip
    assert out["damping"] == {"bending_mode_ratio": 0.002, "contact_dashpot_ratio": 0.01}
    assert out["n_modes"] == 4

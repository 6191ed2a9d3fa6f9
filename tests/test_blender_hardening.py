"""The add-on checks an artist's mesh at set-up and keeps slider values through USD (issue 20);
the checks run inside Blender (bpy_checks_hardening.py)."""

import pytest
from blender_session import bpy_available, shared_session

pytestmark = [pytest.mark.blender,
              pytest.mark.skipif(not bpy_available(), reason="needs the pip bpy module")]


@pytest.fixture(scope="module")
def blender():
    return shared_session()


def test_artist_mesh_is_checked_at_set_up(blender):
    out = blender.run("bpy_checks_hardening:check_artist_mesh")
    assert "cracked" in out["cracked"] and "Weld Cracks" in out["cracked"], out["cracked"]
    assert out["selected"] == out["expected"] and not out["enabled_after_refusal"]
    assert out["welded"] == len(out["expected"]) // 2
    assert out["setup_after_weld"] == ["FINISHED"] and out["warnings_ok_mesh"] == "", out
    assert "non-manifold" in out["fin"], out["fin"]
    assert "look like mm" in out["units"] and "0.001" in out["units"], out["units"]
    assert "only 2 anchor(s)" in out["weak"], out["weak"]


def test_slider_values_beyond_unit_survive_blenders_usd_import(blender, tmp_path):
    out = blender.run("bpy_checks_hardening:check_usd_slider_round_trip", str(tmp_path))
    assert out["peak_mm"] > 2.0
    assert out["UNIT"] < 1e-4, out  # float32 mm
    assert out["SIGNED"] > 0.5, out  # Blender clamps the signed weights 2 and -1.5 to [0, 1]

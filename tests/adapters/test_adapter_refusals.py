"""Scene features an adapter does not write are refused with the field named, never run differently."""
from pathlib import Path

import pytest

from coupler.errors import UnsupportedFeature
from coupler.scene import load_scene

SLIDE = Path(__file__).resolve().parents[2] / "validation" / "cases" / "dem_block_slide" / "block.toml"


def _checker(code):
    if code == "liggghts":
        from adapters.liggghts.writer import check_supported
    else:
        from adapters.yade.params import check_supported
    return check_supported


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_prescribed_cluster_motion_is_written(code):
    """Held / driven clusters are written (tests/adapters/test_prescribed_motion_live.py runs them); an `until`
    shorter than one step is refused with the field named."""
    check = _checker(code)
    check(load_scene(SLIDE, overrides={"dem.clusters[0].motion": {"kind": "fixed"}}))
    check(load_scene(SLIDE, overrides={"dem.clusters[0].motion": {"kind": "velocity", "velocity": [0.1, 0.0, 0.0],
                                                                  "angular_velocity": [0.0, 0.0, 2.0],
                                                                  "until": 0.05}}))
    with pytest.raises(UnsupportedFeature, match=r"dem\.clusters\[0\]\.motion\.until"):
        check(load_scene(SLIDE, overrides={"dem.clusters[0].motion": {"kind": "fixed", "until": 1e-7}}))



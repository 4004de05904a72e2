"""Scene features an adapter does not write are refused with the field named, never run differently."""
from pathlib import Path

import pytest

from coupler.errors import UnsupportedFeature
from coupler.scene import load_scene

SLIDE = Path(__file__).resolve().parents[2] / "validation" / "cases" / "dem_block_slide" / "block.toml"


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_prescribed_cluster_motion_is_refused(code):
    scene = load_scene(SLIDE, overrides={"dem.clusters[0].motion": {"kind": "fixed"}})
    if code == "liggghts":
        from adapters.liggghts.writer import check_supported
    else:
        from adapters.yade.params import check_supported
    with pytest.raises(UnsupportedFeature, match=r"dem\.clusters\[0\]\.motion"):
        check_supported(scene)
    check_supported(load_scene(SLIDE))     # the same scene without the motion is written

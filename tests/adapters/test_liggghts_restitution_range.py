"""Issue 17 item 1: LIGGGHTS takes 0.05 < coefficientRestitution <= 1 (global_properties: "0.05 <
coefficientRestitution <= 1 required"). A contact law whose mapped coefficient falls outside is refused with the pair,
the mapped value and the range (UnsupportedFeature, a SceneError: exit 2), never a traceback."""
import pytest

from adapters.liggghts.writer import check_supported, write_inputs
from coupler.cli import main
from coupler.errors import SceneError, UnsupportedFeature
from coupler.scene import loads_scene
from tests.conftest import BASE_SCENE, edit


@pytest.mark.parametrize("e,damping", [(0.15, "restitution"), (0.05, "restitution"), (0.2, "restitution"),
                                        (0.04, "liggghts"), (0.05, "yade")])
def test_low_restitution_is_refused_with_pair_value_and_range(e, damping, tmp_path):
    scene = loads_scene(edit(BASE_SCENE, "restitution = 0.8", f'restitution = {e}\ndamping = "{damping}"'))
    with pytest.raises(UnsupportedFeature) as ei:
        write_inputs(scene, tmp_path)
    msg = str(ei.value)
    assert ei.value.path == "contacts[0].restitution"
    assert "('aluminium', 'aluminium')" in msg and "0.05 < coefficientRestitution <= 1" in msg, msg
    assert f"restitution {e:g}" in msg, msg


@pytest.mark.parametrize("e", [0.22, 0.5, 1.0])
def test_restitution_inside_the_range_is_written(e, tmp_path):
    scene = loads_scene(edit(BASE_SCENE, "restitution = 0.8", f"restitution = {e}"))
    check_supported(scene)
    write_inputs(scene, tmp_path)
    assert "coefficientRestitution" in (tmp_path / "in.liggghts").read_text()


def test_cli_exits_2_with_one_line(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text(edit(BASE_SCENE, "restitution = 0.8", "restitution = 0.1"))
    assert main(["run", str(p), "--backend", "liggghts", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: contacts[0].restitution:"), err

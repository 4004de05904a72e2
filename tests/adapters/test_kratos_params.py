"""Parameter map native -> Kratos (adapters/kratos/params.py) and what the writer puts into the Kratos input files.
No Kratos needed."""
import json
import math

import numpy as np
import pytest

from adapters.kratos.params import (E_MAX, check_supported, kratos_gamma, kratos_restitution, mpm_law,
                                    restitution_for_gamma)
from adapters.kratos.writer import write_inputs
from coupler.dem.contact import beta_liggghts, beta_restitution, beta_yade
from coupler.errors import UnsupportedFeature
from coupler.scene import ContactLaw, load_scene, loads_scene
from tests.conftest import BASE_SCENE, ROOT

CASES = f"{ROOT}/validation/cases"


def _thornton_kratos(e):
    """sphere_strategy.py GammaForHertzThornton of Kratos 10.4.4, written out independently of beta_yade."""
    if e < 0.001:
        e = 0.001
    if e > 0.999:
        return 0.0
    h = [-6.918798, -16.41105, 146.8049, -796.4559, 2928.711, -7206.864, 11494.29, -11342.18, 6276.757, -1489.915]
    acc = h[-1]
    for c in reversed(h[:-1]):
        acc = c + e * acc
    return math.sqrt(1.0 / (1.0 - (1.0 + e) ** 2 * math.exp(e * acc)) - 1.0)


@pytest.mark.parametrize("e", [0.05, 0.3, 0.5, 0.8, 0.95, 0.999])
def test_kratos_gamma_is_kratos_thornton_fit(e):
    assert kratos_gamma(e) == pytest.approx(_thornton_kratos(e), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("damping,beta", [("restitution", beta_restitution), ("liggghts", beta_liggghts),
                                          ("yade", beta_yade)])
@pytest.mark.parametrize("e", [0.2, 0.5, 0.8, 0.95])
def test_restitution_passed_gives_the_native_beta(damping, beta, e):
    law = ContactLaw(("a", "a"), e, 0.3, damping=damping)
    assert _thornton_kratos(kratos_restitution(law)) == pytest.approx(beta(e), rel=1e-10)


def test_restitution_mode_value_and_yade_identity():
    assert kratos_restitution(ContactLaw(("a", "a"), 0.8, 0.3)) == pytest.approx(0.800066, abs=1e-6)
    assert kratos_restitution(ContactLaw(("a", "a"), 0.8, 0.3, damping="yade")) == 0.8
    assert restitution_for_gamma(0.0) == 1.0
    assert kratos_gamma(E_MAX + 1e-4) == 0.0


def test_materials_json_wall_has_its_own_young_and_pairs(tmp_path):
    scene = load_scene(f"{CASES}/xval_impacts/wall.toml")
    facts = write_inputs(scene, tmp_path)
    m = json.loads((tmp_path / "MaterialsDEM.json").read_text())
    by = {x["material_name"]: x for x in m["materials"]}
    assert by["aluminium__wall"]["Variables"]["YOUNG_MODULUS"] == 70e9
    assert by["aluminium__wall"]["Variables"]["POISSON_RATIO"] == 0.33
    assert by["aluminium"]["Variables"]["PARTICLE_DENSITY"] == 2700.0
    rel = {tuple(r["material_names_list"]): r["Variables"] for r in m["material_relations"]}
    for v in rel.values():
        assert v["DEM_DISCONTINUUM_CONSTITUTIVE_LAW_NAME"] == "DEM_D_Hertz_viscous_Coulomb"
        assert v["STATIC_FRICTION"] == v["DYNAMIC_FRICTION"] == 0.3
        assert _thornton_kratos(v["COEFFICIENT_OF_RESTITUTION"]) == pytest.approx(beta_restitution(0.8), rel=1e-10)
    assert set(rel) == {("aluminium", "aluminium"), ("aluminium", "aluminium__wall")}
    assert ["RigidFacePart.wall_0", "aluminium__wall"] in m["material_assignation_table"]
    p = json.loads((tmp_path / "ProjectParametersDEM.json").read_text())
    assert p["MaxTimeStep"] == 2e-9 and facts["steps"] == 12000 and facts["every"] == 5
    assert p["GlobalDamping"] == 0.0 and p["RollingFrictionOption"] is False
    walls = (tmp_path / "mpmdemDEM_FEM_boundary.mdpa").read_text()
    assert "RigidFace3D4N" in walls and "RigidFace3D3N" not in walls        # one quad: no inner edge


def test_plane_quad_covers_the_reach_and_lies_in_the_plane(tmp_path):
    scene = load_scene(f"{CASES}/xval_impacts/wall.toml", overrides={"dem.spheres[0].velocity": [3.0, -1.0, 0.0]})
    facts = write_inputs(scene, tmp_path)
    c = facts["cover"][0]
    assert c["half"] >= 3.0 * scene.time.t_end + 2.5e-3
    text = (tmp_path / "mpmdemDEM_FEM_boundary.mdpa").read_text().split("Begin Nodes")[1].split("End Nodes")[0]
    ys = [float(l.split()[2]) for l in text.strip().splitlines()]
    assert ys == [0.0] * 4


def test_2d_dem_scene_fixes_out_of_plane_dofs(tmp_path):
    scene = loads_scene(BASE_SCENE.replace("dimension = 3", "dimension = 2")) if "dimension = 3" in BASE_SCENE \
        else None
    if scene is None:
        pytest.skip("base scene has no dimension line")
    facts = write_inputs(scene, tmp_path)
    assert facts["planar"] is True
    assert "n.Fix(KM.VELOCITY_Z)" in (tmp_path / "run_kratos.py").read_text()


def test_unsupported_features_are_named():
    with pytest.raises(UnsupportedFeature, match="tangential"):
        check_supported(load_scene(f"{CASES}/xval_impacts/wall.toml",
                                   overrides={"contacts[0].tangential": "no_history"}))
    bui = load_scene(f"{CASES}/mpm_bui_collapse/scene.toml")
    with pytest.raises(UnsupportedFeature, match=r"mpm\.boundary\.bottom\.kind"):   # Coulomb base: refused
        check_supported(bui, stress_free_start=True)
    with pytest.raises(UnsupportedFeature, match=r"mpm\.bodies\[0\]\.initial_stress"):   # geostatic: refused
        check_supported(bui, friction="fixed")
    check_supported(bui, stress_free_start=True, friction="fixed")   # only when the caller asks for the substitutes
    with pytest.raises(UnsupportedFeature, match=r"mpm\.damping"):
        check_supported(load_scene(f"{CASES}/mpm_bui_collapse/scene.toml", overrides={"mpm.damping": 0.1}),
                        stress_free_start=True, friction="fixed")


def test_mpm_laws_and_grid(tmp_path):
    assert mpm_law("elastic") == "LinearElasticIsotropicPlaneStrain2DLaw"
    assert mpm_law("mohr_coulomb") == "HenckyMCPlasticPlaneStrain2DLaw"
    scene = load_scene(f"{CASES}/mpm_elastic_bar/scene.toml")
    facts = write_inputs(scene, tmp_path, initial_velocity=("0.1*sin(pi*x/0.5)", "0.0"))
    p = json.loads((tmp_path / "ProjectParameters.json").read_text())
    s = p["solver_settings"]
    assert s["time_integration_method"] == "implicit" and s["scheme_type"] == "newmark"
    assert facts["dt"] == pytest.approx(0.1 * 0.01 / 50.0)            # the native CFL step
    mats = json.loads((tmp_path / "ParticleMaterials.json").read_text())["properties"][0]["Material"]
    assert mats["Variables"]["MATERIAL_POINTS_PER_ELEMENT"] == 4 and mats["Variables"]["YOUNG_MODULUS"] == 2500.0
    cons = {c["Parameters"]["model_part_name"]: c["Parameters"]["constrained"]
            for c in p["processes"]["constraints_process_list"]}
    assert cons == {"Background_Grid.BC_left": [True, True, True], "Background_Grid.BC_bottom": [False, True, False],
                    "Background_Grid.BC_top": [False, True, False]}         # right is open
    grid = (tmp_path / "mpmdem_Grid.mdpa").read_text()
    body = (tmp_path / "mpmdem_Body.mdpa").read_text()
    assert grid.count("\n  ", grid.index("Begin Elements"), grid.index("End Elements")) == 50 * 4
    assert body.count("\n  ", body.index("Begin Elements"), body.index("End Elements")) == 25 * 4
    assert "gimp" in facts["shape_note"] and "apic" in facts["transfer_note"]


def test_bui_friction_base_refused_unless_a_substitute_is_named(tmp_path):
    """The rough base (Coulomb mu = 0.36): Kratos 10.4.4's Coulomb wall cannot express it (params.py: its cap is mu x
    the normal force summed over the Newton iterations, its stick penalty creeps every step), so it is refused
    naming the side; friction="fixed" writes the base no-slip (Kratos' own granular_flow_2D example), residual
    criterion, and says so in the facts; the geostatic stress -> stress-free start, stated too."""
    scene = load_scene(f"{CASES}/mpm_bui_collapse/scene.toml", overrides={"mpm.grid.cell_size": 0.02})
    with pytest.raises(UnsupportedFeature, match=r"mpm\.boundary\.bottom\.kind.*Newton iterations"):
        write_inputs(scene, tmp_path, stress_free_start=True)
    facts = write_inputs(scene, tmp_path, stress_free_start=True, friction="fixed")
    assert "stress-free" in facts["initial_stress_note"] and "NO-SLIP" in facts["friction_note"]
    p = json.loads((tmp_path / "ProjectParameters.json").read_text())
    assert p["solver_settings"]["convergence_criterion"] == "residual_criterion"
    assert p["processes"]["list_other_processes"] == []
    cons = {c["Parameters"]["model_part_name"]: c["Parameters"]["constrained"]
            for c in p["processes"]["constraints_process_list"]}
    assert cons == {"Background_Grid.BC_left": [True, False, False], "Background_Grid.BC_right": [True, False, False],
                    "Background_Grid.BC_bottom": [True, True, True]}
    assert "LineCondition2D2N" not in (tmp_path / "mpmdem_Grid.mdpa").read_text()


def test_bui_kratos_slip_wall_corners_and_penalty(tmp_path):
    """friction="kratos_slip" (diagnostics): ApplyMPMSlipBoundaryProcess on the base without its two corner nodes
    (shared with the slip walls: Kratos would rotate their dofs and free the wall-normal motion), which are fixed
    in both normals instead; the stick penalty bounds the summed per-step creep (params.tangential_penalty)."""
    from adapters.kratos.params import CREEP_MAX
    scene = load_scene(f"{CASES}/mpm_bui_collapse/scene.toml", overrides={"mpm.grid.cell_size": 0.02})
    facts = write_inputs(scene, tmp_path, stress_free_start=True, friction="kratos_slip")
    p = json.loads((tmp_path / "ProjectParameters.json").read_text())
    s = p["solver_settings"]
    assert s["convergence_criterion"] == "displacement_criterion"
    assert {"Slip_bottom", "Corner_bottom", "BC_left", "BC_right"} == set(s["processes_sub_model_part_list"])
    (slip,) = p["processes"]["list_other_processes"]
    assert slip["python_module"] == "apply_mpm_slip_boundary_process" and slip["Parameters"]["option"] == "flip_normal"
    assert slip["Parameters"]["friction_coefficient"] == 0.36
    tau = 0.36 * 2650.0 * 9.81 * 0.1
    assert slip["Parameters"]["tangential_penalty_coefficient"] == pytest.approx(facts["steps"] * tau / CREEP_MAX)
    cons = {c["Parameters"]["model_part_name"]: c["Parameters"]["constrained"]
            for c in p["processes"]["constraints_process_list"]}
    assert cons == {"Background_Grid.BC_left": [True, False, False], "Background_Grid.BC_right": [True, False, False],
                    "Background_Grid.Corner_bottom": [False, True, False]}
    grid = (tmp_path / "mpmdem_Grid.mdpa").read_text()
    block = grid.split("Begin Conditions LineCondition2D2N")[1].split("End Conditions")[0].split()
    conds = [tuple(map(int, block[i:i + 4])) for i in range(0, len(block), 4)]
    assert len(conds) == 0.8 / 0.02 - 2                           # one segment per cell, not the two corner ones
    nodes = {int(l.split()[0]): float(l.split()[1]) for l in
             grid.split("Begin Nodes")[1].split("End Nodes")[0].strip().splitlines()}
    assert all(nodes[c[3]] > nodes[c[2]] for c in conds)          # walked in +x (flip_normal: inward normal)
    corner = grid.split("Begin SubModelPart Corner_bottom")[1].split("End SubModelPartNodes")[0].split()[2:]
    assert sorted(nodes[int(i)] for i in corner) == [0.0, 0.8]


def test_cantilever_cosim_files(tmp_path):
    """The coupled scene -> Kratos CoSimulation files: gauss_seidel_weak with DEM first, the DEM contact force mapped
    with use_transpose, 2D DEM discs (CylinderParticle2D) and the interface as RigidEdge2D2N at the MPM point-load
    conditions, the clamped grid side."""
    from adapters.kratos.cosim import write_coupled
    scene = load_scene(f"{CASES}/coupled_kratos_cantilever/scene.toml")
    check_supported(scene)
    facts = write_coupled(scene, tmp_path, 2e-3)
    assert facts["steps"] == 25 and facts["n_interface"] == 41
    cs = json.loads((tmp_path / "ProjectParametersCoSim.json").read_text())["solver_settings"]
    assert cs["type"] == "coupled_solvers.gauss_seidel_weak"
    assert [s["name"] for s in cs["coupling_sequence"]] == ["dem", "mpm"]
    assert cs["coupling_sequence"][1]["input_data_list"][0]["data_transfer_operator_options"] == ["use_transpose"]
    dem = json.loads((tmp_path / "ProjectParametersDEM.json").read_text())
    assert dem["Dimension"] == 2 and dem["MaxTimeStep"] == 2e-3
    assert "CylinderParticle2D" in (tmp_path / "discDEM.mdpa").read_text()
    walls = (tmp_path / "discDEM_FEM_boundary.mdpa").read_text()
    assert walls.count("\n  ", walls.index("Begin Conditions"), walls.index("End Conditions")) == 40
    grid = (tmp_path / "beam_Grid.mdpa").read_text()
    assert "MPMGridPointLoadCondition2D1N" in grid and "INTERFACE_top" in grid
    mp = json.loads((tmp_path / "ProjectParametersMPM.json").read_text())
    (cons,) = mp["processes"]["constraints_process_list"]
    assert cons["Parameters"]["model_part_name"] == "Background_Grid.BC_left"
    rel = json.loads((tmp_path / "MaterialsDEM.json").read_text())["material_relations"]
    wall = next(r for r in rel if r["material_names_list"] == ["disc", "wall"])["Variables"]
    assert wall["STATIC_FRICTION"] == pytest.approx(math.tan(math.radians(30)))
    assert wall["DEM_DISCONTINUUM_CONSTITUTIVE_LAW_NAME"] == "DEM_D_Hertz_viscous_Coulomb2D"


def test_native_equivalent_of_kratos_2d_law_moves_a_layer_like_the_disc():
    """Kratos' DEM_D_Hertz_viscous_Coulomb2D (disc-wall) is linear per unit depth: k' = 0.7854 E*, k_t' = 4 G*/E* k',
    c' = 2 gamma sqrt(m' k'). The native Hooke law on a layer of thickness t must give k / m = k' / m' (m = t m') and
    the same damping ratio gamma (the Kratos DAMPING_GAMMA of the restitution passed)."""
    from adapters.kratos.params import native_beta, native_equivalent_of_2d_law
    from coupler.dem.contact import effective_shear, effective_young
    sc = load_scene(f"{CASES}/coupled_kratos_cantilever/scene.toml")
    disc, wall, t = sc.materials["disc"], sc.materials["beam_wall"], sc.coupling.thickness
    law = sc.contacts[("beam_wall", "disc")]
    f = native_equivalent_of_2d_law(law, disc, wall, t)
    e_star = 1.0 / ((1 - 0.2 ** 2) / 1e6 + 1.0 / 9e7)          # disc E 1e6 nu 0.2, wall E 9e7 nu 0 (scene)
    assert f["normal"]["model"] == "hooke"
    assert f["normal"]["stiffness"] == pytest.approx(t * 0.7854 * e_star, rel=1e-12)
    assert f["normal"]["tangential_ratio"] == pytest.approx(4 * effective_shear(disc, wall) /
                                                            effective_young(disc, wall), rel=1e-12)
    # the native 'restitution' damping of that restitution is Kratos' gamma
    assert beta_restitution(f["restitution"], "hooke") == pytest.approx(kratos_gamma(kratos_restitution(law)),
                                                                         rel=1e-9)
    assert kratos_gamma(kratos_restitution(law)) == pytest.approx(native_beta(law), rel=1e-9)


def test_coupled_retaining_wall_refused_naming_the_clusters(tmp_path, capsys):
    """`mpmdem run <coupled retaining wall> --backend kratos` is one line naming dem.clusters, exit 2, before Kratos
    is needed: Kratos DEM has rigid clusters only as 3D bodies (Cluster3D), its MPM-DEM coupling is 2D
    (params.KRATOS_NO_2D_CLUSTERS)."""
    from coupler.cli import main
    rc = main(["run", f"{CASES}/coupled_retaining_wall/scene.toml", "--backend", "kratos", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert err[0].startswith("error: dem.clusters: not supported by backend 'kratos'") and "Cluster3D" in err[0]


def test_native_same_discretization_of_the_bui_kratos_run():
    """Issue 18's same-work comparison: the overrides that make the native MPM solve what the Kratos Bui run solves
    (bilinear shapes, the no-slip substitute of the friction base, the stress-free start, Kratos' dt, FLIP),
    applied to the implicit case scene; the friction substitute without a native equivalent is refused."""
    from adapters.kratos.params import native_same_discretization
    sc = load_scene(f"{CASES}/mpm_bui_implicit/scene.toml")
    assert sc.mpm.shape != "linear" and sc.mpm.boundary["bottom"].kind == "friction"
    assert sc.mpm.bodies[0].k0 is not None
    ov = native_same_discretization(sc, 2.42e-4, stress_free_start=True, friction="fixed")
    same = load_scene(f"{CASES}/mpm_bui_implicit/scene.toml", overrides=ov)
    assert same.mpm.shape == "linear" and same.mpm.transfer == "musl" and same.time.dt == 2.42e-4
    assert same.mpm.boundary["bottom"].kind == "fixed"
    assert same.mpm.boundary["left"].kind == sc.mpm.boundary["left"].kind == "slip"
    assert same.mpm.bodies[0].k0 is None
    # without the stress-free start the body keeps its geostatic stress (then Kratos refuses the scene)
    assert "mpm.bodies[0].initial_stress" not in native_same_discretization(sc, 1e-4, friction="fixed")
    with pytest.raises(ValueError, match="friction"):
        native_same_discretization(sc, 1e-4, friction="kratos_slip")

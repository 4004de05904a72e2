"""Contact-law definitions and the restitution -> damping maps (numbers from shared/notes/dem_codes.md [ODE]/[RUN])."""
import math

import pytest

from coupler.dem.contact import (beta_liggghts, beta_restitution, beta_yade, effective_shear, effective_young,
                                 restitution_clamped)
from coupler.scene import Material

AL = Material("al", 2700.0, 70e9, 0.33)


def test_effective_moduli_definitions():
    assert effective_young(AL, AL) == pytest.approx(70e9 / (2 * (1 - 0.33 ** 2)), rel=1e-14)
    # G* = E / (4 (2 - nu)(1 + nu)) for equal materials; YADE prints kso = 8 G* sqrt(R*) = 2.2285e9 (R* = 1.25 mm)
    gstar = effective_shear(AL, AL)
    assert gstar == pytest.approx(70e9 / (4 * (2 - 0.33) * (1 + 0.33)), rel=1e-14)
    assert 8 * gstar * math.sqrt(1.25e-3) == pytest.approx(2.2285e9, rel=1e-4)


def test_liggghts_beta_is_sqrt56_of_log_form():
    le = math.log(0.8)
    assert beta_liggghts(0.8) == pytest.approx(math.sqrt(5 / 6) * -le / math.sqrt(le * le + math.pi ** 2), rel=1e-15)
    assert beta_liggghts(0.8) == pytest.approx(0.0646772, abs=1e-7)       # notes P1
    assert beta_liggghts(1.0) == 0.0


def test_yade_thornton_beta_matches_yade():
    assert beta_yade(0.8) == pytest.approx(0.0679029, abs=1e-7)           # notes P1 (YADE en=0.8)


def test_clamped_restitution_of_each_code_definition():
    # notes P2 [ODE]/[RUN]: LIGGGHTS beta with the F >= 0 clamp gives 0.8081; input 0.79117 gives 0.800
    assert restitution_clamped(beta_liggghts(0.8)) == pytest.approx(0.808099, abs=2e-6)
    assert restitution_clamped(beta_liggghts(0.79117)) == pytest.approx(0.800, abs=2e-6)
    assert restitution_clamped(beta_yade(0.8)) == pytest.approx(0.799934, abs=2e-6)
    for e_in, e_out in ((0.5, 0.550), (0.7, 0.718), (0.9, 0.902)):
        assert restitution_clamped(beta_liggghts(e_in)) == pytest.approx(e_out, abs=1e-3)


@pytest.mark.parametrize("e", [0.05, 0.1, 0.3, 0.5, 0.8, 0.95, 0.999])
def test_default_map_inverts_the_clamped_ode(e):
    assert restitution_clamped(beta_restitution(e)) == pytest.approx(e, abs=1e-9)


def test_default_beta_for_08():
    assert beta_restitution(0.8) == pytest.approx(0.067877, abs=2e-6)     # notes P2: "beta_n equiv 0.067877"


@pytest.mark.parametrize("beta", [0.01, 0.3, 0.6675340615054082, 0.99, 1.0, 1.000001, 1.5, 5.0])
def test_clamped_hooke_restitution_closed_form_matches_the_ode(beta):
    """The linear clamped impact's closed form (under-, critically and over-damped) against a direct DOP853
    integration to the force-zero event; and the inverse beta_restitution recovers beta to round-off (the ODE inverse
    was off by 7.6e-9 at the cantilever's beta: step-size noise in e)."""
    from scipy.integrate import solve_ivp
    from coupler.dem.contact.damping import beta_restitution, restitution_clamped

    def rhs(_t, y):
        return [y[1], -max(max(y[0], 0.0) + 2.0 * beta * y[1], 0.0)]

    def force_zero(_t, y):
        return max(y[0], 0.0) + 2.0 * beta * y[1]
    force_zero.terminal, force_zero.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 50.0), [0.0, 1.0], method="DOP853", rtol=1e-12, atol=1e-15, events=(force_zero,))
    e = restitution_clamped(beta, "hooke")
    assert e == pytest.approx(-sol.y[1, -1], rel=1e-8)
    assert beta_restitution(e, "hooke") == pytest.approx(beta, rel=1e-12)

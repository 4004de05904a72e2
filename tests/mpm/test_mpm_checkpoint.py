"""Checkpoint / restart of the MPM, explicit and implicit (MPMSolver.save_checkpoint / load_checkpoint: the solver
pickled whole, the format of the run checkpoints, coupler/checkpoint.py), and the
resumable reference run built on it (validation/cases/mpm_bui_implicit/reference.advance_checkpointed): a run stopped
and resumed from its checkpoint ends bitwise where the uninterrupted run does; a checkpoint of another scene or commit
is refused."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from validation.cases.mpm_bui_implicit import reference as REF

H, T = 0.01, 0.12      # the Bui column at 10 mm (800 points), 0.12 s (the scene outputs every 0.1 s)


def assert_same_frames(a: pd.DataFrame, b: pd.DataFrame) -> None:
    assert list(a.columns) == list(b.columns) and len(a) == len(b)
    for c in a.columns:
        assert np.array_equal(a[c].to_numpy(), b[c].to_numpy()), c


def test_restart_continues_bitwise(tmp_path):
    """150 steps, saved, a fresh solver loads them and takes 184 more (the save falls between two re-orderings of
    the point rows, every 100 steps): the same bits as 334 steps in one go, t and step count included."""
    ref, _ = REF.build_explicit(H, t_end=T)
    ref.advance(334)
    a, _ = REF.build_explicit(H, t_end=T)
    a.advance(150)
    a.save_checkpoint(tmp_path / "c.pkl", {"note": "test"})
    b, _ = REF.build_explicit(H, t_end=T)
    assert b.load_checkpoint(tmp_path / "c.pkl") == {"note": "test"}
    assert b.nstep == 150 and b.t == a.t
    b.advance(184)
    assert b.nstep == ref.nstep and b.t == ref.t
    assert_same_frames(b.particles_frame(), ref.particles_frame())
    assert np.array_equal(b.xb, ref.xb) and np.array_equal(b.drop, ref.drop)
    assert not (tmp_path / "c.pkl.part").exists()


def test_checkpoint_of_another_scene_is_refused(tmp_path):
    a, _ = REF.build_explicit(H, t_end=T)
    a.save_checkpoint(tmp_path / "c.pkl")
    for other in (REF.build_explicit(0.005, t_end=T)[0],                              # other points and grid
                  REF.build_explicit(H, t_end=T, overrides={"mpm.cfl": 0.25})[0]):     # same points, other dt
        with pytest.raises(ValueError, match="written for another scene"):
            other.load_checkpoint(tmp_path / "c.pkl")


def test_implicit_restart_continues_bitwise(tmp_path):
    """The implicit scheme (the case's cfl 5, Newton with the banded LU): 6 steps, saved, a fresh solver loads them
    and takes 7 more: the same bits as 13 in one go (the Newmark acceleration, the LU back-off and the statistics
    come with the pickled solver); an explicit checkpoint is refused by it (another dt and scheme)."""
    imp = {"mpm.scheme": "implicit"}
    ref, _ = REF.build_explicit(H, t_end=T, overrides=imp)
    ref.advance(13)
    a, _ = REF.build_explicit(H, t_end=T, overrides=imp)
    a.advance(6)
    a.save_checkpoint(tmp_path / "i.pkl")
    b, _ = REF.build_explicit(H, t_end=T, overrides=imp)
    b.load_checkpoint(tmp_path / "i.pkl")
    assert b.nstep == 6 and np.array_equal(b.acc, a.acc)
    b.advance(7)
    assert b.nstep == ref.nstep and b.t == ref.t
    assert_same_frames(b.particles_frame(), ref.particles_frame())
    assert np.array_equal(b.acc, ref.acc) and np.array_equal(b.xb, ref.xb)
    assert ref.stats["newton_iterations"] == b.stats["newton_iterations"]
    ex, _ = REF.build_explicit(H, t_end=T)
    ex.save_checkpoint(tmp_path / "e.pkl")
    with pytest.raises(ValueError, match="written for another scene"):
        REF.build_explicit(H, t_end=T, overrides=imp)[0].load_checkpoint(tmp_path / "e.pkl")
    with pytest.raises(ValueError, match="written for another scene"):
        ex.load_checkpoint(tmp_path / "i.pkl")


def test_implicit_checkpoint_refuses_modified_newton(tmp_path):
    from dataclasses import replace
    sol, _ = REF.build_explicit(H, t_end=T, overrides={"mpm.scheme": "implicit"})
    sol.opts = replace(sol.opts, reuse_ratio=0.1)
    with pytest.raises(NotImplementedError, match="reuse_ratio = 0.1"):
        sol.save_checkpoint(tmp_path / "c.pkl")
    assert not (tmp_path / "c.pkl").exists()


class _Stop(Exception):
    pass


def test_resumed_reference_run_is_the_uninterrupted_one(tmp_path, monkeypatch):
    """advance_checkpointed (chunks of 200 steps) saving after every chunk (every = 0 s), the process 'killed' in
    its third chunk: a second call resumes from the checkpoint at step 400 and ends bitwise where advance_to does,
    with two segments that join; a checkpoint of another commit is refused."""
    ref, _ = REF.build_explicit(H, t_end=T)
    k = ref.advance_to(T)
    assert k > 400
    ck = tmp_path / "run.ckpt.pkl"
    sol, _ = REF.build_explicit(H, t_end=T)
    calls = {"n": 0}
    step = sol.advance

    def dying(self, n, dt=None, profile=False):
        calls["n"] += 1
        if calls["n"] == 3:
            raise _Stop
        step(n, dt)

    monkeypatch.setattr(type(sol), "advance", dying)      # on the class: the solver is pickled whole
    with pytest.raises(_Stop):
        REF.advance_checkpointed(sol, T, ck, every=0.0, commit="abc")
    monkeypatch.undo()
    with pytest.raises(ValueError, match="written at commit abc"):
        REF.advance_checkpointed(REF.build_explicit(H, t_end=T)[0], T, ck, every=0.0, commit="def")
    sol2, _ = REF.build_explicit(H, t_end=T)
    segs = REF.advance_checkpointed(sol2, T, ck, every=0.0, commit="abc")
    assert [(s["from_step"], s["to_step"]) for s in segs] == [(0, 400), (400, k)]
    assert all(s["commit"] == "abc" and s["wall_s"] > 0.0 for s in segs)
    assert sol2.t == ref.t == T and sol2.nstep == k
    assert_same_frames(sol2.particles_frame(), ref.particles_frame())

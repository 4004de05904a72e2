"""Restart files of a native run: `mpmdem run --checkpoint-every N` and `mpmdem run --resume` (as LIGGGHTS'
write_restart / read_restart or YADE's O.save / O.load).

A checkpoint is the run's whole state pickled (protocol 5): the solver objects (DEM with its contact history and
neighbour lists, MPM explicit or implicit, or the coupled run with both partitions and the coupling scheme) and the
run loop's own state (counters, the energy, coupling-log and MPM-body rows), with the byte length of every table
file in the output folder at that output time. The tables whose rows grow with the bodies, contacts or coupling steps
(bodies, contacts, interface, the MPM snapshots; the interface series are not held at all) stay on disk: a resumed
run reads the rows written before its checkpoint back (`earlier`, `frames_in`), so a checkpoint grows only by the
energy, log and MPM-body rows, a few hundred bytes per output time. `--resume` truncates every table to its length
at the checkpoint, removes the snapshot files written after it and continues the same loop, so the tables and the final state are bitwise
those of the run that was not stopped (tests/coupler/test_checkpoint.py).

Refused, with one line naming the flag (exit 2): a checkpoint of another scene or of other code (sha256 of the
scene text and of the coupler sources: a pickle is tied to the code that wrote it), a backend other than native,
a coupled run whose DEM partition runs in another process (YADE). Loading a pickle runs code: resume only
checkpoints you wrote. The file is written through a temporary file renamed over the last one, so a run killed
while writing keeps the previous checkpoint.
"""
from __future__ import annotations

import hashlib
import os
import pickle
from dataclasses import dataclass
from pathlib import Path

from coupler.errors import SceneError

FILE = "checkpoint.pkl"
_SRC = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Restart:
    """What `mpmdem run` asked for: a checkpoint every `every` output times (0: none), and/or resume."""
    every: int = 0
    resume: bool = False

    def __post_init__(self):
        if self.every < 0:
            raise SceneError("--checkpoint-every", f"must be >= 0 output times (0: no checkpoints), got {self.every}")

    @property
    def asked(self) -> bool:
        """Checkpoints written or read at all."""
        return bool(self.every or self.resume)


def write_pickle(path, header: dict, body) -> Path:
    """`header` (plain data: what identifies the state) and `body` (the state) pickled one after the other
    (protocol 5) to `path`, through a temporary file renamed over it, so a process killed while writing leaves the
    previous file whole. The one state format of the project: run checkpoints (Checkpoints) and the MPM solver's
    own (MPMSolver.save_checkpoint, the long reference runs)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as f:
        pickle.dump(header, f, protocol=5)
        pickle.dump(body, f, protocol=5)
    os.replace(tmp, path)
    return path


def read_pickle(path, check=None):
    """(header, body) as write_pickle wrote them; `check(header)` runs before the body is read, so a file of
    another scene or code is refused by its header (with the caller's message) before its classes are loaded.
    Loading a pickle runs code: read only files this project wrote."""
    with open(path, "rb") as f:
        header = pickle.load(f)
        if check is not None:
            check(header)
        return header, pickle.load(f)


def code_hash() -> str:
    """sha256 of the coupler package's sources (what a pickled solver's classes and kernels are)."""
    h = hashlib.sha256()
    for p in sorted(_SRC.rglob("*.py")):
        h.update(str(p.relative_to(_SRC)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()


class Checkpoints:
    """One run's checkpoints in <out>/checkpoint.pkl. The run loop calls `resumed()` once before it builds its
    solver (the saved state dict, or None for a fresh run) and `output_done(state)` after each output time's
    record (state: a function returning the dict to save; called only when a checkpoint is due)."""

    def __init__(self, spec: Restart | None, out_dir, scene):
        self.spec = spec or Restart()
        self.out = None if out_dir is None else Path(out_dir)
        if self.spec.asked and self.out is None:
            raise SceneError("--checkpoint-every", "checkpoints need an output folder")
        self.path = None if self.out is None else self.out / FILE
        self.key = {"scene_hash": scene.text_hash, "code": code_hash()} if self.spec.asked else {}
        self.n_outputs = 0           # output times recorded so far (the first, t = 0, included)
        self.written = 0             # checkpoints written by this process
        self.resumed_from: dict | None = None
        self.sizes: dict[str, int] | None = None     # a resumed run: the tables' byte lengths at its checkpoint

    def check(self, solver) -> None:
        """With checkpoints asked for: a SceneError naming the flag when `solver` (an object or a class) says it
        cannot be saved (its checkpoint_refusal(), e.g. the implicit MPM's modified Newton, YADE's partition)."""
        why = getattr(solver, "checkpoint_refusal", lambda: None)() if self.spec.asked else None
        if why:
            raise SceneError("--resume" if self.spec.resume else "--checkpoint-every", why)

    def resumed(self) -> dict | None:
        """With --resume: the saved state, after truncating the tables to their lengths at the checkpoint. A fresh
        run removes a checkpoint an earlier run left in its folder (it would not belong to the new tables)."""
        if not self.spec.resume:
            if self.path is not None and self.path.exists():
                self.path.unlink()
            return None
        if not self.path.exists():
            raise SceneError("--resume", f"no checkpoint at {self.path} (write one with --checkpoint-every N)")

        def same_run(ck):
            for k, v in self.key.items():
                if ck["key"].get(k) != v:
                    what = "scene file" if k == "scene_hash" else "code (coupler sources)"
                    raise SceneError("--resume", f"{self.path} was written by another {what}; rerun without --resume")

        ck, state = read_pickle(self.path, same_run)
        for name, size in ck["files"].items():            # the tables as they were at the checkpoint
            p = self.out / name
            if not p.exists() or p.stat().st_size < size:
                raise SceneError("--resume", f"{p} is shorter than at the checkpoint ({size} bytes): the output "
                                             "folder was changed; rerun without --resume")
            os.truncate(p, size)
        for p in self.out.glob("particles_*.csv"):       # snapshots written after the checkpoint
            if p.name not in ck["files"]:
                p.unlink()
        self.n_outputs = ck["n_outputs"]
        self.sizes = dict(ck["files"])
        self.resumed_from = {"t": ck["t"], "step": ck["step"], "checkpoint": str(self.path)}
        return state

    def output_done(self, t: float, step: int, state, last: bool = False) -> None:
        """One more output time recorded; write a checkpoint when one is due (not after the last output)."""
        self.n_outputs += 1
        k = self.n_outputs - 1                 # the output's index (0: t = 0)
        if not self.spec.every or last or k == 0 or k % self.spec.every:
            return
        files = {p.name: p.stat().st_size for p in sorted(self.out.glob("*.csv"))}
        write_pickle(self.path, {"key": self.key, "t": t, "step": step, "n_outputs": self.n_outputs,
                                 "files": files}, state())
        self.written += 1

    def earlier(self, name: str, **read_csv):
        """A resumed run: the rows of table `name` (e.g. "bodies.csv") written before its checkpoint, read back from
        the file's first bytes as they were then (the tables' digits); None for a fresh run or a table the
        checkpoint did not have. read_csv: pandas.read_csv options (dtypes of the name columns)."""
        if self.sizes is None or name not in self.sizes:
            return None
        import io
        import pandas as pd
        with open(self.out / name, "rb") as f:
            return pd.read_csv(io.BytesIO(f.read(self.sizes[name])), **read_csv)

    def joined(self, name: str, later, **read_csv):
        """Table `name` of the whole run: its rows before the checkpoint (`earlier`) followed by `later` (the rows this
        process computed, a DataFrame or None); `later` alone for a fresh run."""
        import pandas as pd
        before = self.earlier(name, **read_csv)
        if before is None or len(before) == 0:
            return later
        if later is None or len(later) == 0:
            return before
        return pd.concat([before, later], ignore_index=True)

    def dem_tables(self, res, output, body_rows, body_t, names, con) -> None:
        """res.bodies and res.contacts of a run's DEM side from this process's rows (body_rows / body_t per output
        time, con = (con_t, con_i, con_j, con_d)) joined after the rows written before a resumed run's checkpoint;
        tables the scene's [output] does not ask for stay empty."""
        from coupler.results import body_table, contact_table
        bodies = body_table(body_rows, body_t, names) if body_rows else None
        contacts = contact_table(*con) if con[3] and sum(len(d) for d in con[3]) else None
        if output.bodies:
            bodies = self.joined("bodies.csv", bodies, dtype={"body": str})
        if output.contacts:
            contacts = self.joined("contacts.csv", contacts, dtype={"i": str, "j": str})
        if bodies is not None:
            res.bodies = bodies
        if contacts is not None:
            res.contacts = contacts

    @staticmethod
    def frames_out(snaps: list) -> list:
        """The MPM snapshots as a checkpoint keeps them: (t, None), the frame itself being on disk
        (particles_<n>.csv), so that a checkpoint does not grow with every frame held in memory."""
        return [(t, None) for t, _ in snaps]

    def frames_in(self, snaps: list) -> list:
        """The snapshots with the frames of a resumed run's earlier segment read back from particles_<n>.csv (the
        tables' 10 significant digits: the returned Result and the .vtu files of those frames carry them)."""
        import pandas as pd
        return [(t, pd.read_csv(self.out / f"particles_{n}.csv") if df is None else df)
                for n, (t, df) in enumerate(snaps)]

    def summary(self) -> dict:
        """What the run's summary.json says about checkpoints (empty when none were asked for)."""
        if not self.spec.asked:
            return {}
        return {"checkpoints": {"every_outputs": self.spec.every, "written": self.written, "file": FILE,
                                "resumed_from": self.resumed_from,
                                "note": "wall_time_s counts this process only (a resumed run: its last segment)"}}

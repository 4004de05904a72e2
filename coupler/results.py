"""Result tables: the contract every backend (native, LIGGGHTS, YADE, Kratos) fills the same way.

Files written by `Result.write(out_dir)`:
  bodies.csv    t,body,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz   (one row per body per output time)
  contacts.csv  t,i,j,fx,fy,fz,fn,ft,overlap                  (one row per active contact; j = "wall:<name>")
                (fx,fy,fz) is the force on body i; fn >= 0 its normal magnitude, ft >= 0 its tangential magnitude.
  energy.csv    t,kinetic,potential,elastic,dissipated
  mpm_bodies.csv  t,body,mass,x,y,vx,vy,kinetic,ux,uy,ux_max,uy_min,xmin,xmax,ymin,ymax,eps_p_max,n_points
                (one row per MPM body per output time; MPM and coupled runs). Per unit depth
                (2D plane strain): mass [kg/m]; (x, y) centre of mass; (vx, vy) = momentum / mass; kinetic =
                sum 1/2 m v^2 [J/m] of its points (not 1/2 mass |v_cm|^2); (ux, uy) mass-weighted mean displacement
                from the start; ux_max = largest ux of a point, uy_min = lowest uy (largest settlement); xmin ...
                ymax the bounding box of its point centres; eps_p_max the largest accumulated equivalent plastic
                strain; n_points its material points. An MPM body is a deformable continuum with no orientation
                or angular velocity, so it has no rows in bodies.csv (DEM bodies only).
  summary.json  scene, backend, code_version, wall_time_s, steps, dt, particles (+ backend-specific keys)
  particles_<n>.csv for MPM material points, when present (ParaView: vtk/mpm_points, below).
  interface.csv t,fx_dem,fy_dem,fx_mpm,fy_mpm,work_dem,work_mpm  (coupled runs only, one row per coupling step)
                force the DEM puts on the interface wall [N] (time average over the step), force the MPM receives
                [N per unit depth] x thickness [N], cumulative work of each side on the interface [J]
  vtk/*.pvd + *.vtu   ParaView series of all of the above, with `[output] vtk = true` (coupler/vtk.py).
"""
from __future__ import annotations

import csv
import io
import itertools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

BODY_COLUMNS = ["t", "body", "x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz"]
CONTACT_COLUMNS = ["t", "i", "j", "fx", "fy", "fz", "fn", "ft", "overlap"]
ENERGY_COLUMNS = ["t", "kinetic", "potential", "elastic", "dissipated"]
INTERFACE_COLUMNS = ["t", "fx_dem", "fy_dem", "fx_mpm", "fy_mpm", "work_dem", "work_mpm"]
MPM_BODY_COLUMNS = ["t", "body", "mass", "x", "y", "vx", "vy", "kinetic", "ux", "uy", "ux_max", "uy_min", "xmin",
                    "xmax", "ymin", "ymax", "eps_p_max", "n_points"]
SUMMARY_KEYS = ["scene", "backend", "code_version", "wall_time_s", "steps", "dt", "particles"]
# float format of each table's CSV (Result.write and the incremental writes of a running coupled run)
FLOAT_FORMAT = {"bodies": "%.10g", "contacts": "%.10g", "energy": "%.10g", "interface": "%.12g",
                "mpm_bodies": "%.10g", "particles": "%.10g"}


def empty(columns: list[str]) -> pd.DataFrame:
    return pd.DataFrame({c: pd.Series(dtype="object" if c in ("body", "i", "j") else "float64") for c in columns})


_QUOTED = (",", '"', "\n", "\r")       # a string holding one of these is quoted by the csv module


CSV_CHUNK_ROWS = 32768       # rows formatted at once (frame_csv): bounds the Python objects held for one chunk


def _csv_parts(df: pd.DataFrame, float_format: str, header: bool):
    """The CSV text of df as pandas' to_csv(index=False, float_format, header) writes it, as an iterator of parts
    (the header, then CSV_CHUNK_ROWS rows each, formatted as they are asked for), or None when a column is one this
    writer cannot write the same way (frame_csv); the columns are checked before anything is formatted."""
    fmts, arrays = [], []
    for c in df.columns:
        if not isinstance(c, str) or not c or any(ch in c for ch in _QUOTED):
            return None
        col = df[c]
        kind = col.dtype.kind
        if kind == "f":
            a = col.to_numpy()
            if np.isnan(a).any():             # pandas writes NaN as an empty field
                return None
            fmts.append(float_format)
        elif kind in "iu":
            a = col.to_numpy()
            fmts.append("%d")
        elif kind in "OU" or isinstance(col.dtype, pd.StringDtype):
            a = col.to_numpy(dtype=object)
            u = set(a.tolist())
            if not all(isinstance(x, str) and x for x in u) or any(ch in "\x00".join(u) for ch in _QUOTED):
                return None
            fmts.append("%s")
        else:
            return None
        arrays.append(a)
    line = ",".join(fmts) + "\n"

    def parts():
        if header:
            yield ",".join(df.columns) + "\n"
        for lo in range(0, len(df), CSV_CHUNK_ROWS):
            cols = [a[lo:lo + CSV_CHUNK_ROWS].tolist() for a in arrays]
            yield (line * len(cols[0])) % tuple(itertools.chain.from_iterable(zip(*cols)))
    return parts()


def frame_csv(df: pd.DataFrame, float_format: str, header: bool = True) -> str:
    """df.to_csv(index=False, float_format=float_format, header=header), the same characters, ~3x faster for the
    tables written here (an MPM snapshot of 14,780 points: 149 -> 49 ms): one %-format of the values of
    CSV_CHUNK_ROWS rows at a time (floats `float_format`, integers %d, strings %s). A frame it cannot write the same
    way (a NaN, a boolean or mixed column, a string the csv module would quote, an odd column name) goes to pandas
    (tests/coupler/test_frame_csv.py compares the two on random frames)."""
    parts = _csv_parts(df, float_format, header)
    if parts is None:
        return df.to_csv(index=False, float_format=float_format, header=header)
    return "".join(parts)


def write_csv(path: Path, df: pd.DataFrame, float_format: str) -> None:
    """A whole table to `path`, the bytes of pandas' to_csv, written a chunk of rows at a time (frame_csv)."""
    parts = _csv_parts(df, float_format, True)
    if parts is None:
        df.to_csv(path, index=False, float_format=float_format)
        return
    with open(path, "w", encoding="utf-8") as f:
        f.writelines(parts)


def append_csv(path: Path, df: pd.DataFrame, float_format: str, first: bool) -> None:
    """Write rows of a table that grows during a run: with the header (a new file) when `first`, else appended;
    one write per call, flushed, so a run that stops (error or kill) keeps every chunk written before, readable."""
    text = frame_csv(df, float_format, header=first)
    with open(path, "w" if first else "a") as f:
        f.write(text)
        f.flush()


def body_table(rows: list[np.ndarray], times: list[float], names: list[str]) -> pd.DataFrame:
    """bodies.csv from per-output arrays of shape (n_bodies, 13) (BODY_COLUMNS after t, body) and their times."""
    df = pd.DataFrame(np.vstack(rows), columns=BODY_COLUMNS[2:])
    df.insert(0, "body", np.tile(np.array(names, dtype=object), len(rows)))
    df.insert(0, "t", np.repeat(np.array(times), len(names)))
    return df


def contact_table(times: list[np.ndarray], i: list[str], j: list[str], data: list[np.ndarray]) -> pd.DataFrame:
    """contacts.csv from per-output contact rows: times, body names i / j and (n, 6) arrays fx, fy, fz, fn, ft,
    overlap."""
    d = np.vstack(data)
    return pd.DataFrame({"t": np.concatenate(times), "i": i, "j": j, "fx": d[:, 0], "fy": d[:, 1], "fz": d[:, 2],
                         "fn": d[:, 3], "ft": d[:, 4], "overlap": d[:, 5]})[CONTACT_COLUMNS]


@dataclass
class Result:
    bodies: pd.DataFrame = field(default_factory=lambda: empty(BODY_COLUMNS))
    contacts: pd.DataFrame = field(default_factory=lambda: empty(CONTACT_COLUMNS))
    energy: pd.DataFrame = field(default_factory=lambda: empty(ENERGY_COLUMNS))
    summary: dict = field(default_factory=dict)
    particles: list[tuple[float, pd.DataFrame]] = field(default_factory=list)  # MPM snapshots (t, table)
    interface: pd.DataFrame | None = None   # coupled runs: INTERFACE_COLUMNS
    mpm_bodies: pd.DataFrame = field(default_factory=lambda: empty(MPM_BODY_COLUMNS))  # MPM body table
    # the folder a ResultStream (or run_coupled) already wrote the tables into: Result.write does not write them again
    streamed: Path | None = field(default=None, repr=False, compare=False)

    def check(self) -> None:
        """Raise if a table does not follow the contract (backends call this before returning)."""
        for name, df, cols in (("bodies", self.bodies, BODY_COLUMNS), ("contacts", self.contacts, CONTACT_COLUMNS),
                               ("energy", self.energy, ENERGY_COLUMNS),
                               ("mpm_bodies", self.mpm_bodies, MPM_BODY_COLUMNS)):
            if list(df.columns) != cols:
                raise ValueError(f"{name} table columns {list(df.columns)} != contract {cols}")
        missing = [k for k in SUMMARY_KEYS if k not in self.summary]
        if missing:
            raise ValueError(f"summary is missing keys {missing}")

    def body(self, name: str) -> pd.DataFrame:
        """Rows of one body, sorted by time."""
        df = self.bodies[self.bodies["body"] == name]
        return df.sort_values("t").reset_index(drop=True)

    def mpm_body(self, name: str) -> pd.DataFrame:
        """Rows of one MPM body, sorted by time."""
        df = self.mpm_bodies[self.mpm_bodies["body"] == name]
        return df.sort_values("t").reset_index(drop=True)

    def write(self, out_dir: str | Path, scene=None) -> Path:
        """Write the tables; with a scene whose `[output] vtk = true`, also the ParaView series (coupler/vtk.py)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        # the run wrote its tables into this folder as it went (ResultStream, run_coupled's _Tables): they are not
        # written again (nor read back, for a StreamedResult), and every snapshot is there
        done = self.streamed == out.resolve()
        for name in ("bodies", "contacts", "energy", "interface", "mpm_bodies"):
            if done and (out / f"{name}.csv").exists():
                continue
            df = getattr(self, name)
            if df is not None and (len(df) or name != "mpm_bodies"):
                write_csv(out / f"{name}.csv", df, FLOAT_FORMAT[name])
        if not done:
            for n, (t, df) in enumerate(self.particles):
                write_csv(out / f"particles_{n}.csv", df, FLOAT_FORMAT["particles"])
        (out / "summary.json").write_text(json.dumps(_jsonable(self.summary), indent=2) + "\n")
        if scene is not None and scene.output.vtk:
            from coupler.vtk import write_vtk   # ParaView series from these same tables (every backend alike)
            write_vtk(self, out, scene)
        return out

    @classmethod
    def read(cls, out_dir: str | Path) -> "Result":
        out = Path(out_dir)
        return cls(bodies=read_table(out, "bodies"), contacts=read_table(out, "contacts"),
                   energy=read_table(out, "energy"), summary=json.loads((out / "summary.json").read_text()),
                   particles=read_particles(out), interface=read_table(out, "interface"),
                   mpm_bodies=read_table(out, "mpm_bodies"))


_DTYPES = {"bodies": {"body": str}, "contacts": {"i": str, "j": str}, "mpm_bodies": {"body": str}}


def read_table(out: Path, name: str) -> pd.DataFrame | None:
    """Table `name` of a run folder (stored reference runs keep theirs gzip-compressed). A missing mpm_bodies table
    is empty, a missing interface table None (not a coupled run)."""
    p = out / f"{name}.csv"
    p = p if p.exists() else out / f"{name}.csv.gz"
    if not p.exists() and name in ("mpm_bodies", "interface"):
        return empty(MPM_BODY_COLUMNS) if name == "mpm_bodies" else None
    return pd.read_csv(p, **({"dtype": _DTYPES[name]} if name in _DTYPES else {}))


def read_particles(out: Path) -> list[tuple[float, pd.DataFrame]]:
    """The MPM snapshots of a run folder, (t, frame) in order."""
    particles = []
    for p in sorted(out.glob("particles_*.csv"), key=lambda p: int(p.stem.split("_")[1])):
        df = pd.read_csv(p)
        particles.append((float(df["t"].iloc[0]) if len(df) and "t" in df else float("nan"), df))
    return particles


def _on_disk(name: str) -> property:
    """A table of a StreamedResult: read from its file when first used, then kept."""
    def get(self):
        if name not in self._tables:
            self._tables[name] = read_particles(self.out) if name == "particles" else read_table(self.out, name)
        return self._tables[name]

    def put(self, value):
        self._tables[name] = value
    return property(get, put)


class StreamedResult(Result):
    """The Result of a native run whose large tables (bodies, contacts, MPM snapshots: they grow with the bodies
    times the output times) were written to `out` as it went and are not held in memory:
    `run_scene(..., keep_tables=False)`, as `mpmdem run` calls it. Each is read back from its file when first used
    (the files' 10 significant digits, as `Result.read`). Before the thirty-sixth session every run held them
    until it ended: 2 GB for 50,000 spheres and 100 output times. The small tables (energy, mpm_bodies, interface)
    are kept as computed."""
    bodies = _on_disk("bodies")
    contacts = _on_disk("contacts")
    particles = _on_disk("particles")

    def __init__(self, out: Path, summary: dict, energy: pd.DataFrame, mpm_bodies: pd.DataFrame | None = None,
                 interface: pd.DataFrame | None = None):
        self._tables: dict = {}
        self.out = Path(out).resolve()
        self.summary = summary
        self.energy = energy
        self.mpm_bodies = empty(MPM_BODY_COLUMNS) if mpm_bodies is None else mpm_bodies
        self.interface = interface
        self.streamed = self.out

    def check(self) -> None:
        """The tables on disk were written with the contract's columns (ResultStream); the summary is checked."""
        missing = [k for k in SUMMARY_KEYS if k not in self.summary]
        if missing:
            raise ValueError(f"summary is missing keys {missing}")


ROW_FORMAT = FLOAT_FORMAT["bodies"]      # ResultStream rows: bodies, contacts, energy, mpm_bodies (all "%.10g")
TABLES = {"bodies": BODY_COLUMNS, "contacts": CONTACT_COLUMNS, "energy": ENERGY_COLUMNS,
          "mpm_bodies": MPM_BODY_COLUMNS}


class ResultStream:
    """The result tables of a native run written as it goes (issue #17): at every output time the new rows are
    appended to <out>/<table>.csv, each table's chunk as one write() system call on a file opened O_APPEND, so a
    run that stops (blow-up, SIGKILL) leaves every table complete up to an output time and readable by
    `Result.read`; a kill between two tables' writes leaves them at most one output time apart. The bytes are
    those `Result.write` produces for the whole table (same columns, same float format): `Result.write` skips the
    tables a stream has written into the same folder. summary.json says `status = "running"` until the run's
    final summary replaces it; `stopped(err)` records a SimulationError (step, body, quantity, last output time).
    MPM snapshots go to particles_<n>.csv through a temporary file and a rename (never half written)."""

    def __init__(self, out_dir: str | Path, tables: list[str], summary: dict, resume: tuple | None = None):
        """resume = (t_last, n_snapshots) of a run continued from a checkpoint (coupler/checkpoint.py truncated
        its tables to that output time): append to the tables as they are."""
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.fds: dict[str, int] = {}
        self.t_last, self.n_snapshots = resume or (None, 0)
        self.summary = dict(summary)
        for name in tables:
            if name != "particles":
                flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | (0 if resume else os.O_TRUNC)
                fd = os.open(self.out / f"{name}.csv", flags, 0o644)
                self.fds[name] = fd
                if not resume:
                    _write_all(fd, empty(TABLES[name]).to_csv(index=False).encode())
        if not resume:
            for old in self.out.glob("particles_*.csv"):          # snapshots of an earlier run in this folder
                old.unlink()
        self._summary({"status": "running"})

    def _summary(self, extra: dict) -> None:
        tmp = self.out / "summary.json.tmp"
        tmp.write_text(json.dumps(_jsonable({**self.summary, **extra}), indent=2) + "\n")
        os.replace(tmp, self.out / "summary.json")

    def append(self, t: float, tables: dict[str, list], particles: pd.DataFrame | None = None) -> None:
        """The rows of one output time (call it after that time's health and energy checks passed): per table a
        list of rows, each row its values in the table's column order, or a DataFrame of the table's columns
        (written by frame_csv: the same characters, without a Python list per row)."""
        for name, rows in tables.items():
            if len(rows):
                text = frame_csv(rows, ROW_FORMAT, header=False) if isinstance(rows, pd.DataFrame) else csv_rows(rows)
                _write_all(self.fds[name], text.encode() if isinstance(text, str) else text)
        if particles is not None:
            p = self.out / f"particles_{self.n_snapshots}.csv"
            write_csv(p.with_suffix(".tmp"), particles, FLOAT_FORMAT["particles"])
            os.replace(p.with_suffix(".tmp"), p)
            self.n_snapshots += 1
        self.t_last = t

    def close(self) -> None:
        for fd in self.fds.values():
            os.close(fd)
        self.fds = {}

    def stopped(self, err) -> None:
        """The run stopped with `err` (a SimulationError): close the tables, say why in summary.json."""
        self.close()
        self._summary({"status": "stopped", "error": str(err), "step": getattr(err, "step", None),
                       "body": getattr(err, "body", None), "quantity": getattr(err, "quantity", None),
                       "t_stopped": getattr(err, "t", None), "t_last_output": self.t_last})

    def finish(self, result: "Result") -> None:
        """The run ended: the result's final tables are the streamed ones (Result.write does not rewrite them)."""
        self.close()
        result.streamed = self.out.resolve()


def csv_rows(rows) -> bytes:
    """CSV lines as pandas' to_csv(float_format=ROW_FORMAT) writes them: floats "%.10g" (NaN empty), integers
    and strings as they are (quoted by the csv module where needed), without building a DataFrame per output time
    (that tripled the output cost of a 1-sphere DEM run)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    for row in rows:
        w.writerow([(ROW_FORMAT % v if v == v else "") if isinstance(v, (float, np.floating)) else v for v in row])
    return buf.getvalue().encode()


def _write_all(fd: int, data: bytes) -> None:
    while data:
        data = data[os.write(fd, data):]


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    return x

"""LAMMPS itself writes a small 3D granular dump (particles poured in at the top, evaporated at
the bottom) and the importer is checked against the engine's own numbers: the thermo log's
atom count at every dump step and an independent plain-text reading of the dump files.

Skipped where LAMMPS is not installed (CI); a LAMMPS that is installed but fails is a failure.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.io import import_file
from cfbmarkov.simulate.dem.lammps import find_lammps, run_lammps
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_info import describe

DT = 1e-5
EVERY = 500                 # steps between dumps (and thermo lines)
STEPS = 10000
#: the box in LAMMPS's coordinates, off the origin so that the region's corner matters
BOX = ((-0.01, 0.01), (0.1, 0.11), (0.2, 0.26))
GRAN = "hooke/history 500 NULL 5000 NULL 0.5 1"

# Up to 30 spheres of 1 mm poured into a slab near the top ({volume}: the volume fraction of
# each insertion, 0.004 gives batches of 11, 0.0004 one sphere at a time); gravity along -z
# (the LIGGGHTS convention); up to 4 atoms deleted every 100 steps from the bottom 10 mm.
# One file per dump step without ITEM: TIME (like LIGGGHTS post/dump*), and one file with it.
DECK = f"""
units si
atom_style sphere
dimension 3
boundary f f f
comm_modify vel yes
region box block {BOX[0][0]} {BOX[0][1]} {BOX[1][0]} {BOX[1][1]} {BOX[2][0]} {BOX[2][1]} units box
create_box 1 box
pair_style gran/{GRAN}
pair_coeff * *
neighbor 0.0002 bin
neigh_modify delay 0 every 1 check yes
timestep {DT}
fix integrate all nve/sphere
fix weight all gravity 9.81 vector 0 0 -1
fix walls_x all wall/gran {GRAN} xplane {BOX[0][0]} {BOX[0][1]}
fix walls_y all wall/gran {GRAN} yplane {BOX[1][0]} {BOX[1][1]}
fix floor all wall/gran {GRAN} zplane {BOX[2][0]} NULL
region slab block -0.009 0.009 0.101 0.109 0.245 0.255 units box
fix feed all pour 30 1 4767548 region slab diam one 0.001 dens 2500 2500 vol {{volume}} 50 &
    vel 0 0 0 0 -0.3
region bottom block {BOX[0][0]} {BOX[0][1]} {BOX[1][0]} {BOX[1][1]} {BOX[2][0]} 0.21 units box
fix drain all evaporate 100 4 bottom 9876
thermo_style custom step atoms
thermo {EVERY}
dump each all custom {EVERY} dump.*.lammpstrj id type x y z vx vy vz
dump one all custom {EVERY} run.lammpstrj id type x y z vx vy vz
dump_modify one time yes
run {STEPS}
"""


def read_dump(path: Path) -> list[dict]:
    """Every frame of a LAMMPS text dump, read plainly: timestep, time (or None), box flags
    and bounds, and the atom table as {id: (x, y, z, vx, vy, vz)}."""
    frames = []
    lines = path.read_text().splitlines()
    i, frame = 0, {"time": None}
    while i < len(lines):
        item = lines[i]
        if item == "ITEM: TIME":
            frame["time"] = float(lines[i + 1])
            i += 2
        elif item == "ITEM: TIMESTEP":
            frame["step"] = int(lines[i + 1])
            i += 2
        elif item == "ITEM: NUMBER OF ATOMS":
            count = int(lines[i + 1])
            i += 2
        elif item.startswith("ITEM: BOX BOUNDS"):
            frame["flags"] = item.split()[3:]
            frame["box"] = [tuple(float(v) for v in lines[i + 1 + k].split()) for k in range(3)]
            i += 4
        else:
            assert item.startswith("ITEM: ATOMS"), (path, i, item)
            names = item.split()[2:]
            rows = [dict(zip(names, line.split())) for line in lines[i + 1:i + 1 + count]]
            frame["atoms"] = {int(r["id"]): tuple(float(r[c]) for c in ("x", "y", "z", "vx", "vy", "vz"))
                              for r in rows}
            frames.append(frame)
            i, frame = i + 1 + count, {"time": None}
    return frames


def thermo_atoms(log: Path) -> dict[int, int]:
    """{step: atoms} from the thermo table of a LAMMPS log."""
    counts, inside = {}, False
    for line in log.read_text().splitlines():
        fields = line.split()
        if fields == ["Step", "Atoms"]:
            inside = True
        elif inside and line.startswith("Loop time"):
            inside = False
        elif inside:
            counts[int(fields[0])] = int(fields[1])
    return counts


def expected_frames(files: list[Path]) -> list[dict]:
    """The engine's frames in timestep order, from the first that holds atoms (the importer
    has nothing to store before any atom exists)."""
    frames = sorted((f for path in files for f in read_dump(path)), key=lambda f: f["step"])
    first = next(k for k, f in enumerate(frames) if f["atoms"])
    return frames[first:]


def check_against_engine(path: Path, frames: list[dict], log_counts: dict[int, int],
                         times: np.ndarray) -> np.ndarray:
    """Compare an imported trajectory file with the engine's frames; returns its positions."""
    lo = np.array([b[0] for b in BOX])
    with Trajectories(path) as t:
        assert t.dimensions == 3
        assert t.boundary == "open"                         # 'f' on the vertical axis z
        assert t.axes == {"across": "x", "vertical": "z", "depth": "y"}
        np.testing.assert_array_equal(t.region_origin, lo[[0, 2, 1]])
        np.testing.assert_allclose(t.times, times, rtol=1e-12, atol=0)
        # the dump frames before the first atom (step 0 here) are skipped, and said so
        assert t.parameters["frames_without_atoms_skipped"] == STEPS // EVERY + 1 - len(frames)

        all_ids = sorted(set().union(*(f["atoms"] for f in frames)))
        assert sorted(t.ids.tolist()) == all_ids
        column = {int(i): k for k, i in enumerate(t.ids)}
        present, pos, vel = t.present(), t.positions(), t.velocities()
        assert present.shape == pos.shape[:2] == (len(frames), len(all_ids))

        for k, frame in enumerate(frames):
            ids = set(frame["atoms"])
            assert {int(i) for i in t.ids[present[k]]} == ids, f"step {frame['step']}"
            assert len(ids) == log_counts[frame["step"]], f"step {frame['step']}"
            absent = ~present[k]
            assert np.isnan(pos[k, absent]).all()
            for i, (x, y, z, vx, vy, vz) in frame["atoms"].items():
                want = np.array([x, z, y]) - lo[[0, 2, 1]]   # (across, vertical, depth)
                np.testing.assert_allclose(pos[k, column[i]], want, rtol=0, atol=1e-15)
                np.testing.assert_array_equal(vel[k, column[i]], [vx, vz, vy])

        entries = sum(len(set(b["atoms"]) - set(a["atoms"])) for a, b in zip(frames, frames[1:]))
        exits = sum(len(set(a["atoms"]) - set(b["atoms"])) for a, b in zip(frames, frames[1:]))
        counts = [len(f["atoms"]) for f in frames]
        info = describe(t)
        assert (f"  particles present per frame: min {min(counts)}, max {max(counts)} "
                f"of {len(all_ids)}") in info
        assert f"  tracks begun {entries}, ended {exits} (after the first frame, anywhere" in info
        return pos


@pytest.mark.skipif(find_lammps() is None, reason="LAMMPS is not installed (lmp not found)")
@pytest.mark.parametrize("feed", ["batches", "one at a time"])
def test_lammps_pour_and_evaporate_dump_imports_as_the_engine_wrote_it(tmp_path, feed):
    folder = tmp_path / "lammps"
    folder.mkdir()
    script = folder / "in.pour"
    script.write_text(DECK.format(volume=0.004 if feed == "batches" else 0.0004))
    run_lammps(script, find_lammps(), ranks=1, timeout=120)   # fails with LAMMPS's message
    log_counts = thermo_atoms(folder / "log.lammps")
    assert sorted(log_counts) == list(range(0, STEPS + 1, EVERY))

    # one file per dump step, no ITEM: TIME: times are timestep x DT
    files = sorted(folder.glob("dump.*.lammpstrj"))
    assert len(files) == STEPS // EVERY + 1
    frames = expected_frames(files)
    first = frames[0]
    assert first["flags"] == ["ff", "ff", "ff"] and first["time"] is None
    np.testing.assert_allclose(first["box"], BOX, rtol=1e-15)
    counts = [len(f["atoms"]) for f in frames]
    # the deck does what it says: atoms come in (in batches, or first a single one: its z
    # alone cannot show that the dump is 3D), and in batches later they go
    assert max(counts) > counts[0]
    assert counts[-1] < max(counts) if feed == "batches" else counts[0] == 1
    assert len(frames) >= 15
    steps = np.array([f["step"] for f in frames])
    out = import_file(str(folder / "dump.*.lammpstrj"), "lammps", tmp_path / "each.h5",
                      time_step=DT, vertical_axis="z")
    pos_each = check_against_engine(out, frames, log_counts, steps * DT)

    # the same run as a single file with ITEM: TIME, and the region given explicitly
    frames_one = expected_frames([folder / "run.lammpstrj"])
    assert [f["step"] for f in frames_one] == steps.tolist()
    assert all(f["atoms"] == g["atoms"] for f, g in zip(frames, frames_one))
    times = np.array([f["time"] for f in frames_one])
    out = import_file(folder / "run.lammpstrj", "lammps", tmp_path / "one.h5",
                      vertical_axis="z", region=BOX)
    pos_one = check_against_engine(out, frames_one, log_counts, times)
    np.testing.assert_array_equal(pos_one, pos_each)

    # a 3D dump is never guessed: without the vertical axis it is refused
    for source in (str(folder / "dump.*.lammpstrj"), folder / "run.lammpstrj"):
        with pytest.raises(InputError, match="--vertical-axis"):
            import_file(source, "lammps", tmp_path / "guess.h5", time_step=DT)
        assert not (tmp_path / "guess.h5").exists()

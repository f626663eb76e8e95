"""ParaView export (cfbmarkov.io.vtk): files, values read back from pyevtk's binary format,
frame selection, gas fields, bad arguments and atomic output."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pyevtk.hl
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.io.vtk import export_vtk, export_vtk_summary
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_format import lap_increments
from cfbmarkov.trajectory_writer import write_trajectories

W, H = 0.09, 0.95
T, N = 10, 50
T0, DT = 0.5, 0.025
NX, NY = 3, 5
DX, DY = W / NX, H / NY


# -- generated data ---------------------------------------------------------------------------
def make_run(path: Path, *, velocities: bool = True, fields: bool = True,
             field_frames=None, seed: int = 0) -> dict:
    """A run of N particles x T frames; with ``fields``, a /fields group on an NX x NY grid
    holding the frames ``field_frames`` (default all). Returns the arrays written."""
    rng = np.random.default_rng(seed)
    times = T0 + DT * np.arange(T)
    pos = np.stack([rng.uniform(0, W, (T, N)), rng.uniform(0, H, (T, N))], axis=-1)
    vel = rng.normal(0.0, 1.0, (T, N, 2))
    # laps consistent with the positions (minimal-image passes), from random starting laps
    steps = lap_increments(pos[:-1, :, 1], pos[1:, :, 1], H)
    laps = (rng.integers(-3, 4, (1, N))
            + np.concatenate([np.zeros((1, N), int), np.cumsum(steps, axis=0)])).astype(np.int32)
    ids = 1000 + 7 * rng.permutation(N)          # not sorted: the file's order must be kept
    write_trajectories(path, times, pos, width=W, height=H, ids=ids,
                       velocities=vel if velocities else None, laps=laps)
    data = dict(times=times, pos=pos, vel=vel, laps=laps, ids=ids)
    if fields:
        k = np.arange(T) if field_frames is None else np.asarray(field_frames)
        j, i = np.mgrid[0:NY, 0:NX]
        # [t, ny, nx]: (100 t + 10 j + i) / 1e4, a fraction that names its place
        vf = ((k[:, None, None] * 100 + j * 10 + i) / 1e4).astype(np.float32)
        gv = np.stack([vf + 0.5, -vf], axis=-1)
        with h5py.File(path, "a") as f:
            g = f.create_group("fields")
            g.attrs["spacing"] = [DX, DY]
            g.attrs["origin"] = [0.0, 0.0]
            g.attrs["shape"] = [NX, NY]
            g["time"] = times[k]
            g["void_fraction"] = vf
            g["gas_velocity"] = gv
            g["pressure"] = 2.0 * vf
        data.update(field_frames=k, void_fraction=vf, gas_velocity=gv, pressure=2.0 * vf)
    return data


@pytest.fixture
def run(tmp_path):
    path = tmp_path / "run.h5"
    return path, make_run(path)


# -- reading pyevtk's files back ----------------------------------------------------------------
VTK_TYPES = {"Float64": "<f8", "Float32": "<f4", "Int64": "<i8", "Int32": "<i4", "Int8": "<i1",
             "UInt8": "<u1"}


def read_vtk(path: Path) -> tuple[ET.Element, dict[str, np.ndarray]]:
    """Parse a pyevtk XML file with raw appended data: (header XML, {array name: values}),
    vector arrays as [n, components]. Each appended block is a UInt64 byte count then the
    little-endian values; the XML gives each array's offset after the '_' marker."""
    raw = path.read_bytes()
    marker = b'<AppendedData encoding="raw">'
    cut = raw.index(marker)
    root = ET.fromstring(raw[:cut] + b"</VTKFile>")
    assert root.get("header_type") == "UInt64" and root.get("byte_order") == "LittleEndian"
    binary = raw[raw.index(b"_", cut + len(marker)) + 1:]
    arrays = {}
    for el in root.iter("DataArray"):
        assert el.get("format") == "appended"
        offset = int(el.get("offset"))
        nbytes = int(np.frombuffer(binary, "<u8", 1, offset)[0])
        dtype = np.dtype(VTK_TYPES[el.get("type")])
        values = np.frombuffer(binary, dtype, nbytes // dtype.itemsize, offset + 8)
        ncomp = int(el.get("NumberOfComponents"))
        arrays[el.get("Name")] = values.reshape(-1, ncomp) if ncomp > 1 else values
    return root, arrays


def read_pvd(path: Path) -> list[tuple[float, str]]:
    root = ET.parse(path).getroot()
    assert root.get("type") == "Collection"
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".tmp-" in p.name or ".old-" in p.name)


# -- tests --------------------------------------------------------------------------------------
def test_exports_every_frame_with_collections(run, tmp_path):
    path, data = run
    out = tmp_path / "deep" / "vtk"
    result = export_vtk(path, out)
    assert result == out and out.is_dir()
    assert sorted(p.name for p in out.glob("*.vtu")) == [f"particles_{k:06d}.vtu" for k in range(T)]
    assert sorted(p.name for p in out.glob("*.vtr")) == [f"gas_{k:06d}.vtr" for k in range(T)]
    for stem, ext in (("particles", "vtu"), ("gas", "vtr")):
        entries = read_pvd(out / f"{stem}.pvd")
        assert [f for _, f in entries] == [f"{stem}_{k:06d}.{ext}" for k in range(T)]
        np.testing.assert_allclose([t for t, _ in entries], data["times"], rtol=1e-15)
    assert leftovers(out.parent) == []


def test_particle_values_read_back(run, tmp_path):
    path, data = run
    out = export_vtk(path, tmp_path / "vtk", start=T0 + 2 * DT)   # first exported frame: 2
    purple = (data["pos"][2, :, 0] < W / 2).astype(np.int8)
    assert 0 < purple.sum() < N
    for k in (2, 7):
        root, arrays = read_vtk(out / f"particles_{k:06d}.vtu")
        piece = root.find("UnstructuredGrid/Piece")
        assert int(piece.get("NumberOfPoints")) == N
        expected_points = np.column_stack([data["pos"][k], np.zeros(N)])
        np.testing.assert_array_equal(arrays["points"], expected_points)
        np.testing.assert_array_equal(arrays["id"], data["ids"])
        assert arrays["id"].dtype == np.int64
        np.testing.assert_array_equal(arrays["lap"], data["laps"][k])
        assert arrays["lap"].dtype == np.int32
        # the colour groups are those of the first exported frame, not of frame k
        np.testing.assert_array_equal(arrays["colour_group"], purple)
        assert arrays["colour_group"].dtype == np.int8
        np.testing.assert_array_equal(arrays["velocity"],
                                      np.column_stack([data["vel"][k], np.zeros(N)]))
        np.testing.assert_allclose(arrays["speed"], np.hypot(*data["vel"][k].T), rtol=1e-15)
        names = {el.get("Name"): int(el.get("NumberOfComponents"))
                 for el in piece.find("PointData")}
        assert names == {"colour_group": 1, "id": 1, "lap": 1, "speed": 1, "velocity": 3}
        if k != 2:   # the test means something: frame k's own halves differ
            assert not np.array_equal(purple, data["pos"][k, :, 0] < W / 2)


def test_gas_grid_read_back(run, tmp_path):
    path, data = run
    out = export_vtk(path, tmp_path / "vtk")
    k = 4
    root, arrays = read_vtk(out / f"gas_{k:06d}.vtr")
    grid = root.find("RectilinearGrid")
    assert grid.get("WholeExtent") == f"0 {NX} 0 {NY} 0 0"
    np.testing.assert_allclose(arrays["x_coordinates"], DX * np.arange(NX + 1), rtol=1e-15)
    np.testing.assert_allclose(arrays["y_coordinates"], DY * np.arange(NY + 1), rtol=1e-15)
    np.testing.assert_array_equal(arrays["z_coordinates"], [0.0])
    names = {el.get("Name"): int(el.get("NumberOfComponents"))
             for el in grid.find("Piece/CellData")}
    assert names == {"void_fraction": 1, "pressure": 1, "gas_velocity": 3}
    # VTK numbers cells with x fastest: cell (i, j) is value 10 j + i at index j * NX + i
    vf = arrays["void_fraction"]
    assert vf.size == NX * NY
    assert vf[0] == np.float32(k / 100) and vf[1] == np.float32((100 * k + 1) / 1e4)
    assert vf[NX] == np.float32((100 * k + 10) / 1e4)
    np.testing.assert_array_equal(vf, data["void_fraction"][k].ravel())
    np.testing.assert_array_equal(arrays["pressure"], data["pressure"][k].ravel())
    gv = data["gas_velocity"][k].reshape(-1, 2)
    np.testing.assert_array_equal(arrays["gas_velocity"], np.column_stack([gv, np.zeros(NX * NY)]))


@pytest.mark.parametrize("start, stop, every, frames", [
    (T0 + 2 * DT, T0 + 6 * DT, 1, [2, 3, 4, 5, 6]),
    (None, None, 3, [0, 3, 6, 9]),
    (T0 + 1 * DT, None, 4, [1, 5, 9]),
    (None, T0 + 4.5 * DT, 2, [0, 2, 4]),
    (T0 + 3 * DT, T0 + 3 * DT, 1, [3]),
])
def test_window_and_stride_select_frames(run, tmp_path, start, stop, every, frames):
    path, data = run
    summary = export_vtk_summary(path, tmp_path / "vtk", start=start, stop=stop, every=every)
    out = summary.output
    assert summary.frames.tolist() == frames
    assert summary.n_particle_files == summary.n_gas_files == len(frames)
    assert sorted(p.name for p in out.glob("*.vtu")) == [f"particles_{k:06d}.vtu" for k in frames]
    assert sorted(p.name for p in out.glob("*.vtr")) == [f"gas_{k:06d}.vtr" for k in frames]
    entries = read_pvd(out / "particles.pvd")
    np.testing.assert_allclose([t for t, _ in entries], data["times"][frames], rtol=1e-15)
    _, arrays = read_vtk(out / f"particles_{frames[-1]:06d}.vtu")
    np.testing.assert_array_equal(arrays["colour_group"], data["pos"][frames[0], :, 0] < W / 2)


def test_without_fields_writes_particles_only(tmp_path):
    path = tmp_path / "run.h5"
    data = make_run(path, velocities=False, fields=False)
    out = export_vtk(path, tmp_path / "vtk", every=5)
    assert sorted(p.name for p in out.iterdir()) == [
        "particles.pvd", "particles_000000.vtu", "particles_000005.vtu"]
    _, arrays = read_vtk(out / "particles_000005.vtu")
    assert set(arrays) == {"points", "connectivity", "offsets", "types", "colour_group", "id", "lap",
                           "cfbmarkov_periodic"}
    np.testing.assert_array_equal(arrays["lap"], data["laps"][5])
    # the riser's periodicity per axis, for an import of the export: y (vertical) periodic
    np.testing.assert_array_equal(arrays["cfbmarkov_periodic"].ravel(), [0, 1, 0])


def test_fields_false_skips_gas(run, tmp_path):
    path, _ = run
    summary = export_vtk_summary(path, tmp_path / "vtk", fields=False)
    assert summary.n_gas_files == 0 and summary.n_gas_missing == 0
    assert not list(summary.output.glob("gas*"))


def test_frames_without_gas_field_are_skipped_and_counted(tmp_path):
    path = tmp_path / "run.h5"
    make_run(path, field_frames=[0, 2, 4, 6, 8])
    with pytest.warns(UserWarning, match="5 of 10 exported frames have no gas field"):
        summary = export_vtk_summary(path, tmp_path / "vtk")
    assert (summary.n_particle_files, summary.n_gas_files, summary.n_gas_missing) == (10, 5, 5)
    assert [f for _, f in read_pvd(summary.output / "gas.pvd")] == [
        f"gas_{k:06d}.vtr" for k in (0, 2, 4, 6, 8)]
    _, arrays = read_vtk(summary.output / "gas_000004.vtr")
    # the gas frame matched by time, the group's 3rd
    assert arrays["void_fraction"][0] == np.float32(4 * 100 / 1e4)


def test_open_trajectories_stay_open_and_progress_bar(run, tmp_path, capsys):
    path, data = run
    with Trajectories(path) as traj:
        export_vtk(traj, tmp_path / "vtk", every=9, progress=True)
        np.testing.assert_array_equal(traj.positions(1), data["pos"][1])   # still readable
    err = capsys.readouterr().err
    # stderr is no terminal here: whole lines, no bar's carriage returns
    lines = err.splitlines()
    assert "\r" not in err and lines[0].startswith("export vtk: ") and lines[0].endswith(
        " frames") and re.match(r"export vtk: \d+ frames in ", lines[-1])


def test_reexport_replaces_a_previous_export(run, tmp_path):
    path, _ = run
    out = tmp_path / "vtk"
    export_vtk(path, out)
    export_vtk(path, out, every=5)
    assert sorted(p.name for p in out.glob("*.vtu")) == ["particles_000000.vtu", "particles_000005.vtu"]
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("kwargs, match", [
    (dict(start=0.0, stop=0.6), "outside the data"),
    (dict(start=T0 + 20 * DT), "outside the data"),
    (dict(stop=0.1), "outside the data|empty"),
    (dict(start=T0 + 0.5 * DT, stop=T0 + 0.7 * DT), "holds no frame"),
    (dict(start=T0 + 0.5 * DT, stop=T0 + 0.5 * DT), "no frame at"),
    (dict(every=0), "every 0"),
    (dict(every=1.5), "every 1.5"),
    (dict(start=float("nan")), "not a finite number"),
])
def test_bad_arguments_raise_and_write_nothing(run, tmp_path, kwargs, match):
    path, _ = run
    out = tmp_path / "new" / "vtk"
    with pytest.raises(InputError, match=match) as info:
        export_vtk(path, out, **kwargs)
    assert "\n" not in str(info.value)
    assert not (tmp_path / "new").exists()


def test_output_that_is_a_file_or_a_foreign_folder_is_refused(run, tmp_path):
    path, _ = run
    target = tmp_path / "out.txt"
    target.write_text("keep")
    with pytest.raises(InputError, match="is a file"):
        export_vtk(path, target)
    assert target.read_text() == "keep"
    with pytest.raises(InputError, match="overwrite the input"):
        export_vtk(path, path)
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("keep")
    with pytest.raises(InputError, match="not part of a VTK export"):
        export_vtk(path, folder)
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]
    assert leftovers(tmp_path) == []


def test_damaged_fields_group_is_refused(run, tmp_path):
    path, _ = run
    with h5py.File(path, "a") as f:
        del f["fields/pressure"]
        f["fields/pressure"] = np.zeros((T, NX, NY), dtype=np.float32)   # transposed
    with pytest.raises(InputError, match="damaged /fields group.*'pressure' has shape"):
        export_vtk(path, tmp_path / "vtk")
    assert not (tmp_path / "vtk").exists() and leftovers(tmp_path) == []


@pytest.mark.parametrize("name, value, said", [
    ("void_fraction", 7.0, "not a fraction between 0 and 1"),
    ("void_fraction", np.nan, "not a fraction between 0 and 1"),
    ("pressure", np.inf, "not a finite number"),
])
def test_a_field_value_out_of_range_is_refused_not_drawn(run, tmp_path, name, value, said):
    """A NaN or a void fraction of 7 in a stored field was written into the .vtr files; the
    export is refused, naming the field and time, and leaves nothing."""
    path, _ = run
    with h5py.File(path, "a") as f:
        f[f"fields/{name}"][1, 0, 0] = value
    with pytest.raises(InputError, match=f"damaged /fields group: {name} at t = .* holds 1 "
                                         f"value\\(s\\) {said}"):
        export_vtk(path, tmp_path / "vtk")
    assert not (tmp_path / "vtk").exists() and leftovers(tmp_path) == []
    export_vtk(path, tmp_path / "particles", fields=False)


@pytest.mark.parametrize("previous", [False, True])
def test_error_mid_export_leaves_no_partial_output(run, tmp_path, monkeypatch, previous):
    path, _ = run
    out = tmp_path / "vtk"
    if previous:
        export_vtk(path, out, every=3)
    before = sorted(p.name for p in out.iterdir()) if previous else None
    real = pyevtk.hl.pointsToVTK
    calls = []

    def failing(*args, **kwargs):
        calls.append(args[0])
        if len(calls) == 3:
            raise RuntimeError("disk on fire")
        return real(*args, **kwargs)

    monkeypatch.setattr(pyevtk.hl, "pointsToVTK", failing)
    with pytest.raises(RuntimeError, match="disk on fire"):
        export_vtk(path, out)
    assert len(calls) == 3 and ".tmp-" in Path(calls[0]).parent.name   # written beside, not in out
    if previous:
        assert sorted(p.name for p in out.iterdir()) == before   # the old export is untouched
    else:
        assert not out.exists()
    assert leftovers(tmp_path) == []


def test_3d_file_exports_depth_as_z(tmp_path):
    """A 3D file: points (x, y, z) with z the depth, velocity with its z component."""
    rng = np.random.default_rng(3)
    depth = 0.02
    times = T0 + DT * np.arange(3)
    pos = rng.uniform(0, 1, (3, N, 3)) * [W, H, depth]
    vel = rng.normal(0.0, 1.0, (3, N, 3))
    path = write_trajectories(tmp_path / "run3.h5", times, pos, width=W, height=H, depth=depth,
                              velocities=vel)
    out = export_vtk(path, tmp_path / "vtk")
    _, arrays = read_vtk(out / "particles_000001.vtu")
    np.testing.assert_array_equal(arrays["points"], pos[1])
    np.testing.assert_array_equal(arrays["velocity"], vel[1])
    np.testing.assert_allclose(arrays["speed"], np.linalg.norm(vel[1], axis=-1), rtol=1e-15)


def test_absent_particles_are_left_out_of_their_frames(tmp_path):
    """An open riser: each frame's points are the particles present in it; a particle absent
    from the first exported frame has no tracer group (-1)."""
    rng = np.random.default_rng(4)
    times = T0 + DT * np.arange(3)
    pos = rng.uniform(0, 1, (3, N, 2)) * [W, H]
    present = np.ones((3, N), bool)
    present[0, 1] = False                # enters at the second frame
    present[2, 0] = False                # leaves after the second frame
    path = write_trajectories(tmp_path / "open.h5", times, pos, width=W, height=H,
                              present=present, boundary="open")
    out = export_vtk(path, tmp_path / "vtk")
    for k in range(3):
        _, arrays = read_vtk(out / f"particles_{k:06d}.vtu")
        np.testing.assert_array_equal(arrays["id"], np.flatnonzero(present[k]))
        np.testing.assert_array_equal(arrays["points"][:, :2], pos[k][present[k]])
    _, arrays = read_vtk(out / "particles_000001.vtu")
    expected = (pos[0, :, 0] < W / 2).astype(int)
    expected[1] = -1
    np.testing.assert_array_equal(arrays["colour_group"], expected[present[1]])


def test_a_frame_without_particles_is_a_file_without_points(tmp_path):
    """An open riser emptied for a frame (every particle absent): the frame is a .vtu with
    no point and every array empty (pyevtk refuses a piece without points), in the series
    at its time; the frames around it keep their points."""
    rng = np.random.default_rng(5)
    times = T0 + DT * np.arange(3)
    pos = rng.uniform(0, 1, (3, N, 2)) * [W, H]
    present = np.ones((3, N), bool)
    present[1] = False                   # nobody in the riser at the second frame
    path = write_trajectories(tmp_path / "open.h5", times, pos, width=W, height=H,
                              present=present, boundary="open")
    out = export_vtk(path, tmp_path / "vtk")
    root, arrays = read_vtk(out / "particles_000001.vtu")
    assert root.find(".//Piece").get("NumberOfPoints") == "0"
    assert set(arrays) >= {"points", "id", "lap", "colour_group"}
    assert all(values.size == 0 for name, values in arrays.items()
               if name != "cfbmarkov_periodic")
    np.testing.assert_array_equal(arrays["cfbmarkov_periodic"].ravel(), [0, 0, 0])  # open
    assert arrays["points"].shape == (0, 3)
    _, full = read_vtk(out / "particles_000002.vtu")
    np.testing.assert_array_equal(full["id"], np.arange(N))
    assert [name for _, name in read_pvd(out / "particles.pvd")] == [
        f"particles_{k:06d}.vtu" for k in range(3)]


def test_an_open_export_whose_first_frame_is_empty_imports_back_open(tmp_path):
    """A riser that starts empty: its export's first frame has no point. Reading a file of
    no points had crashed the import with a traceback (any .vtp/.vtu series, MFiX's before
    its first injection too), and the empty frame carried no periodicity, so the export
    would have come back periodic."""
    from cfbmarkov.io import import_file
    from cfbmarkov.trajectory_writer import write_trajectories

    times = 0.01 * np.arange(6)
    pos = np.full((6, 2, 2), 0.05)
    pos[:, :, 1] = 0.02 + 0.03 * np.arange(6)[:, None]
    present = np.ones((6, 2), bool)
    present[:2] = False                      # nobody yet
    src = write_trajectories(tmp_path / "open.h5", times, pos, width=0.1, height=0.2,
                             present=present, boundary="open")
    export_vtk(src, tmp_path / "vtk")
    first = (tmp_path / "vtk" / "particles_000000.vtu").read_bytes()
    assert b'NumberOfPoints="0"' in first and b'Name="cfbmarkov_periodic"' in first
    back = import_file(tmp_path / "vtk", None, tmp_path / "back.h5",
                       region=((0, 0.1), (0, 0.2)))
    with Trajectories(back) as t, Trajectories(src) as s:
        assert t.boundary.is_open
        np.testing.assert_array_equal(t.present(), s.present())
        np.testing.assert_allclose(t.positions()[2:], s.positions()[2:])

"""resample_tracks: irregular rows onto a uniform grid, the presence rule, periodic laps, refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cfbmarkov.errors import InputError
from cfbmarkov.io.resample import ResampledTracks, resample_tracks

FIELD = Path(__file__).parent / "field"
H = 0.95


def _rows(*tracks):
    """Rows (times, particles, positions) from (id, times [n], positions [n, D]) tracks."""
    times = np.concatenate([t for _, t, _ in tracks])
    ids = np.concatenate([np.full(len(t), i, dtype=np.int64) for i, t, _ in tracks])
    pos = np.concatenate([p for _, _, p in tracks])
    return times, ids, pos


def test_pept_field_file_resamples_onto_the_truth_with_the_gap_absent():
    """tests/io/field/pept-pointdata.csv: t in ms, x y z in mm, y = 2.5 t mod 950 mm,
    x = 45 + 20 sin(t / 50) mm; samples 0.459..297.155 ms and 420.451..784.662 ms: frames on
    the multiples of 5 ms within them, 5..780 ms."""
    data = np.loadtxt(FIELD / "pept-pointdata.csv", comments="#")
    t, xyz = data[:, 0] / 1000, data[:, 1:4] / 1000
    out = resample_tracks(t, np.zeros(len(t), dtype=np.int64), xyz, interval=0.005, max_gap=0.1,
                          height=H, vertical=1)
    assert isinstance(out, ResampledTracks)
    np.testing.assert_array_equal(out.ids, [0])
    g = out.times * 1000                                  # ms
    np.testing.assert_array_equal(out.times, np.round(np.arange(1, 157) * 0.005, 12))
    assert g[0] == 5.0 and g[-1] == 780.0 and len(g) == 156
    expected = (g <= 297.1547) | (g >= 420.4513)
    assert expected.sum() == 59 + 72 and (~expected).sum() == 25
    np.testing.assert_array_equal(out.present[:, 0], expected)
    assert np.isnan(out.positions[~expected, 0]).all() and (out.laps[~expected, 0] == 0).all()
    here = out.positions[expected, 0] * 1000              # mm
    gp = g[expected]
    np.testing.assert_allclose(here[:, 0], 45 + 20 * np.sin(gp / 50), rtol=0, atol=0.5)
    dy = np.abs(here[:, 1] - np.mod(2.5 * gp, 950))       # 760 ms lies on the top: 0 or 950
    assert np.minimum(dy, 950 - dy).max() < 0.5
    np.testing.assert_allclose(here[:, 2], 0.5, rtol=0, atol=1e-12)
    assert (here[:, 1] >= 0).all() and (here[:, 1] < 950).all()
    # the pass at 380 ms lies inside the gap, unseen: the laps carry on from 0 after it;
    # the pass at 760 ms is seen: one more lap from then on (the frame at 760 ms lies on the
    # top within the samples' round-off, just below it)
    laps = out.laps[expected, 0]
    np.testing.assert_array_equal(laps, np.where(gp < 762, 0, 1))
    adjacent = np.diff(np.flatnonzero(expected)) == 1     # not across the gap
    wrapped = np.flatnonzero((np.diff(here[:, 1]) < 0) & adjacent)
    assert not adjacent.all() and here[59, 1] < here[58, 1]  # y fell across the gap: no lap
    np.testing.assert_array_equal(np.flatnonzero(np.diff(laps)), wrapped)
    assert np.diff(laps)[wrapped].tolist() == [1] and gp[wrapped + 1][0] == pytest.approx(765.0)


def test_samples_on_grid_times_are_reproduced_exactly_and_between_is_linear():
    rng = np.random.default_rng(3)
    interval, start = 0.01, 0.2
    on = start + np.arange(0, 30, 3) * interval           # every third grid time
    off = start + (np.arange(0, 27, 3) + 1.5) * interval  # half-way between them
    t = np.concatenate([on, off])
    pos = np.column_stack([rng.uniform(0, 0.09, len(t)), rng.uniform(0, H, len(t))])
    out = resample_tracks(t, np.full(len(t), 4), pos, interval=interval, max_gap=0.05, height=H,
                          max_step=0.5)
    k = np.arange(0, 30, 3)
    np.testing.assert_allclose(out.times[k], on, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out.positions[k, 0], pos[:len(on)])
    assert out.present.all()
    # grid time 1 lies a third of the way from the sample at 0 to the one at 1.5 intervals
    w = 1 / 1.5
    a, b = pos[0], pos[len(on)]
    dy = b[1] - a[1] - H * np.round((b[1] - a[1]) / H)
    assert out.positions[1, 0, 0] == pytest.approx(a[0] + w * (b[0] - a[0]), abs=1e-15)
    assert out.positions[1, 0, 1] == pytest.approx(np.mod(a[1] + w * dy, H), abs=1e-15)


def test_frames_lie_on_multiples_of_the_step_and_interpolate_the_samples_around_them():
    """Samples from 0.0123 s, 7 ms apart: frames at the multiples of 5 ms within their span
    (0.015 ... 0.08 s, round numbers), each the linear interpolation of its two samples."""
    t = 0.0123 + 0.007 * np.arange(11)                  # 0.0123 .. 0.0823 s
    pos = np.column_stack([0.01 + 0.5 * t, 0.1 + 2.0 * t])   # linear: exact interpolation
    out = resample_tracks(t, np.zeros(11, dtype=np.int64), pos, interval=0.005, max_gap=0.008)
    assert out.times[0] == 0.015 and out.times[-1] == 0.08 and len(out.times) == 14
    assert [float(v) for v in out.times] == [round(0.005 * k, 12) for k in range(3, 17)]
    assert out.present.all()
    np.testing.assert_allclose(out.positions[:, 0, 0], 0.01 + 0.5 * out.times, atol=1e-15)
    np.testing.assert_allclose(out.positions[:, 0, 1], 0.1 + 2.0 * out.times, atol=1e-15)


def test_late_particle_is_absent_before_its_first_sample_and_after_its_last():
    t7 = np.linspace(0.0, 1.0, 51)                        # 0.02 s apart, the whole span
    t3 = 0.42 + 0.02 * np.arange(19)                      # 0.42 .. 0.78 s, off the 0.05 grid
    p7 = np.column_stack([np.full(51, 0.03), 0.1 + 0.5 * t7])
    p3 = np.column_stack([np.full(19, 0.06), 0.2 + 0.25 * (t3 - 0.42)])
    out = resample_tracks(*_rows((7, t7, p7), (3, t3, p3)), interval=0.05, max_gap=0.03)
    np.testing.assert_array_equal(out.ids, [3, 7])
    assert len(out.times) == 21 and out.present[:, 1].all()
    expected = (out.times > 0.42) & (out.times < 0.78)
    np.testing.assert_array_equal(out.present[:, 0], expected)
    assert expected.sum() == 7                            # 0.45 .. 0.75 s
    assert np.isnan(out.positions[~expected, 0]).all() and (out.laps == 0).all()
    np.testing.assert_allclose(out.positions[expected, 0, 1], 0.2 + 0.25 * (out.times[expected] - 0.42),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.positions[:, 1, 1], 0.1 + 0.5 * out.times, rtol=0, atol=1e-12)


def test_max_gap_smaller_than_the_interval_and_at_the_edge():
    t = np.array([0.0, 0.004, 0.01, 0.013, 0.02, 0.03, 0.034])
    pos = np.column_stack([np.zeros(7), t])
    out = resample_tracks(t, np.ones(7, dtype=np.int64), pos, interval=0.005, max_gap=0.004)
    # grid 0, 5, 10, ... 30 ms: on a sample (0, 10, 20, 30), or inside a step <= 4 ms (none here:
    # 5 ms lies in the 6 ms step 4..10, 15 in 13..20, 25 in 20..30)
    np.testing.assert_array_equal(out.present[:, 0], [1, 0, 1, 0, 1, 0, 1])
    out = resample_tracks(t, np.ones(7, dtype=np.int64), pos, interval=0.005, max_gap=0.006)
    np.testing.assert_array_equal(out.present[:, 0], [1, 1, 1, 0, 1, 0, 1])


def test_laps_count_both_ways_and_carry_on_across_a_gap():
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4, 1.0, 1.1, 1.2])
    y = np.array([0.5, 0.8, 0.1, 0.85, 0.6, 0.9, 0.05, 0.3])  # up, down, ..., gap, up
    out = resample_tracks(t, np.zeros(8), np.column_stack([np.zeros(8), y]), interval=0.1,
                          max_gap=0.15, height=H, max_step=0.4)
    present = np.zeros(13, dtype=bool)
    present[[0, 1, 2, 3, 4, 10, 11, 12]] = True
    np.testing.assert_array_equal(out.present[:, 0], present)
    np.testing.assert_array_equal(out.laps[:, 0], [0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1])
    np.testing.assert_allclose(out.positions[present, 0, 1], y, rtol=0, atol=1e-15)


def test_coarse_vertical_step_is_refused_naming_the_particle():
    t = np.array([0.0, 0.1, 0.2])
    pos = np.column_stack([np.zeros(3), [0.1, 0.2, 0.2 + 0.3 * H]])
    with pytest.raises(InputError, match=r"particle 42 moves \+0\.285 m vertically between t = 0\.1 "
                                         r"and 0\.2 s.*give --max-gap below 0\.1 s.*or give unwrapped coordinates"):
        resample_tracks(t, np.full(3, 42), pos, interval=0.1, height=H)
    # the same step across a gap (longer than max_gap) is no step: not refused
    t = np.array([0.0, 0.1, 0.5])
    out = resample_tracks(t, np.full(3, 42), pos, interval=0.1, height=H)
    np.testing.assert_array_equal(out.present[:, 0], [1, 1, 0, 0, 0, 1])
    # and a looser max_step lets it through
    resample_tracks(np.array([0.0, 0.1, 0.2]), np.full(3, 42), pos, interval=0.1, height=H,
                    max_step=0.35)


def test_a_bridged_gap_the_tracer_outruns_is_refused():
    """A tracer rising at 5 m/s, sampled every 2 ms, unseen for 150 ms: it rose 0.75 m
    (0.79 H) there, which the heights read as 0.2 m down, a pass up lost and a fall that never
    happened. Its speed before and after the gap says it could move 0.75 m, more than a
    quarter of H: bridged with --max-gap 0.2 it is refused naming a --max-gap that leaves the
    gap out; a slow tracer (0.5 m/s, 0.075 m in the gap) is bridged."""
    t = np.concatenate([np.arange(0.0, 0.3, 0.002), np.arange(0.45, 0.7, 0.002)])
    for speed, refused in ((5.0, True), (0.5, False)):
        pos = np.column_stack([np.full(t.size, 0.04), np.mod(0.1 + speed * t, H)])
        if refused:
            with pytest.raises(InputError, match=r"particle 7 moves at \+5 m/s or faster "
                               r"vertically before and after its samples at t = 0\.298 and "
                               r"0\.45 s .*so between them it can move \+0\.76 m.*give "
                               r"--max-gap below 0\.152 s"):
                resample_tracks(t, np.full(t.size, 7), pos, interval=0.005, max_gap=0.2,
                                height=H)
            out = resample_tracks(t, np.full(t.size, 7), pos, interval=0.005, max_gap=0.1,
                                  height=H)
            assert not out.present[70, 0]          # 0.35 s: in the gap, absent
        else:
            out = resample_tracks(t, np.full(t.size, 7), pos, interval=0.005, max_gap=0.2,
                                  height=H)
            assert out.present.all()
            unwrapped = out.positions[:, 0, 1] + H * out.laps[:, 0]
            np.testing.assert_allclose(unwrapped, 0.1 + speed * out.times, atol=1e-9)


def test_location_noise_over_close_samples_is_not_read_as_speed():
    """A tracer rising at 2.5 m/s located every 1.5 ms on average (some samples microseconds
    apart) with 3 mm of location error, bridged with the docs' --max-gap 0.02: a speed from
    two close samples is mostly their error (96 m/s was read), so the speed is fitted over
    50 ms on each side and nothing is refused; nor is a tracer that turns in a gap."""
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.exponential(0.0015, 20000))
    pos = np.column_stack([np.full(t.size, 0.04),
                           np.mod(0.1 + 2.5 * t + rng.normal(0, 0.003, t.size), H)])
    out = resample_tracks(t, np.zeros(t.size, np.int64), pos, interval=0.005, max_gap=0.02,
                          height=H)
    assert out.present.mean() > 0.95
    # rising at 3 m/s, unseen 0.1 s at the top of its path, falling at 3 m/s after
    t = np.concatenate([np.arange(0.0, 0.3, 0.002), np.arange(0.4, 0.7, 0.002)])
    y = np.where(t < 0.35, 0.1 + 3.0 * t, 0.1 + 3.0 * 0.35 - 3.0 * (t - 0.35))
    pos = np.column_stack([np.full(t.size, 0.04), np.mod(y, H)])
    resample_tracks(t, np.zeros(t.size, np.int64), pos, interval=0.005, max_gap=0.15,
                    height=H)


GOOD = (np.array([0.0, 0.5, 1.0]), np.zeros(3, dtype=np.int64), np.full((3, 2), 0.1))


@pytest.mark.parametrize("change, match", [
    ({"interval": 0.0}, r"--resample .*positive finite number, not 0\.0"),
    ({"interval": -0.1}, r"--resample"),
    ({"interval": np.nan}, r"--resample"),
    ({"interval": np.inf}, r"--resample"),
    ({"interval": "often"}, r"--resample"),
    ({"interval": 2.0}, r"--resample step 2 s is larger than the span 1 s of the data"),
    ({"max_gap": 0.0}, r"--max-gap must be a positive finite number"),
    ({"max_gap": np.inf}, r"--max-gap"),
    ({"times": np.array([])}, r"no rows to resample \(--resample"),
    ({"times": np.array([0.0, np.nan, 1.0])}, r"1 row\(s\) have a non-finite time.*row 1"),
    ({"positions": np.array([[0.1, 0.1], [0.1, np.inf], [0.1, 0.1]])}, r"non-finite position"),
    ({"times": np.array([0.0, 1.0, 1.0])}, r"particle 0 has two rows at t = 1 s"),
    ({"positions": np.zeros((3, 4))}, r"do not agree"),
    ({"particles": np.array([0.0, 0.5, 1.0])}, r"whole numbers"),
    ({"vertical": 2}, r"vertical column 2"),
    ({"height": -1.0}, r"height must be a positive"),
])
def test_bad_input_is_refused_in_one_line(change, match):
    args = dict(zip(("times", "particles", "positions"), GOOD), interval=0.25)
    args.update(change)
    with pytest.raises(InputError, match=match) as info:
        resample_tracks(args.pop("times"), args.pop("particles"), args.pop("positions"), **args)
    assert "\n" not in str(info.value)


def test_open_riser_interpolates_a_jump_and_keeps_laps_zero():
    t = np.array([0.0, 0.1, 0.2])
    pos = np.column_stack([np.zeros(3), [0.9, 0.15, 2.0]])   # no wrapping: straight through
    out = resample_tracks(t, np.zeros(3), pos, interval=0.05, max_gap=0.1)
    np.testing.assert_allclose(out.positions[:, 0, 1], [0.9, 0.525, 0.15, 1.075, 2.0],
                               rtol=0, atol=1e-15)
    assert out.present.all() and (out.laps == 0).all() and out.laps.dtype == np.int32
    # the same rows in a periodic riser: 0.9 -> 0.15 passes the top, 2.0 is 0.1 in [0, H)
    periodic = resample_tracks(t, np.zeros(3), pos, interval=0.05, max_gap=0.1, height=H)
    np.testing.assert_allclose(periodic.positions[:, 0, 1], [0.9, 0.05, 0.15, 0.125, 0.1],
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(periodic.laps[:, 0], [0, 1, 1, 1, 1])


def test_shuffled_rows_give_the_identical_result():
    rng = np.random.default_rng(11)
    tracks = []
    for pid, (t0, t1) in zip((5, 1, 9), ((0.0, 2.0), (0.3, 1.7), (0.6, 2.0))):
        t = np.sort(rng.uniform(t0, t1, 300))
        y = np.mod(0.3 + 1.3 * t + 0.01 * rng.standard_normal(300), H)
        tracks.append((pid, t, np.column_stack([rng.uniform(0, 0.09, 300), y, rng.uniform(0, 0.01, 300)])))
    times, ids, pos = _rows(*tracks)
    a = resample_tracks(times, ids, pos, interval=0.01, max_gap=0.03, height=H)
    perm = rng.permutation(len(times))
    b = resample_tracks(times[perm], ids[perm], pos[perm], interval=0.01, max_gap=0.03, height=H)
    assert a.present.any(axis=0).all() and a.laps.max() >= 1
    for name in ("times", "ids", "positions", "present", "laps"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_an_open_riser_does_not_interpolate_across_a_return_through_the_faces():
    """A tracer leaving an open view at the top and coming back at the bottom 9 ms later:
    no height is interpolated across the riser between the two samples; it is absent
    there, its two stretches an exit and an entry. The periodic riser joins them by the
    minimal-image rule instead."""
    t = np.array([0.750, 0.7598, 0.7690, 0.780])
    y = np.array([0.925, 0.9496, 0.0225, 0.050])
    xy = np.stack([np.full(4, 0.045), y], axis=1)
    ids = np.zeros(4, dtype=np.int64)
    open_riser = resample_tracks(t, ids, xy, interval=0.005, max_gap=0.02, open_height=0.95)
    at = {round(float(g), 3): k for k, g in enumerate(open_riser.times)}
    assert not open_riser.present[at[0.765], 0]
    assert open_riser.present[at[0.755], 0] and open_riser.present[at[0.775], 0]
    periodic = resample_tracks(t, ids, xy, interval=0.005, max_gap=0.02, height=0.95)
    assert periodic.present[at[0.765], 0]
    # through the top: 0.9496 + (0.0225 + 0.95 - 0.9496) * 5.2 / 9.2, wrapped
    assert periodic.positions[at[0.765], 0, 1] == pytest.approx(
        (0.9496 + (0.0225 + 0.95 - 0.9496) * (0.765 - 0.7598) / (0.7690 - 0.7598)) - 0.95)
    assert periodic.laps[at[0.765], 0] == 1


def test_tracers_under_a_column_of_another_name_are_refused_not_merged(tmp_path, capsys):
    """Two PEPT tracers numbered by a column the import does not know ('tid'): read as one
    tracer the samples jump between them, which resampling would smooth into a plausible
    path; the import refuses, naming the column. Named 'tracer', each is a particle; one
    tracer with a whole-number column that does not split its samples (a detector number)
    imports."""
    from cfbmarkov.cli import main
    from cfbmarkov.trajectories import Trajectories

    rng = np.random.default_rng(4)
    t = np.sort(rng.uniform(0, 400, 600))                     # ms
    tracer = rng.integers(0, 2, t.size)
    x = np.where(tracer == 0, 25.0, 65.0) + 2 * np.sin(t / 50)  # mm
    y = (100 + 2.0 * t + 300 * tracer) % 950                  # 2 m/s up
    detector = rng.integers(1, 4, t.size)

    def write(name, column):
        path = tmp_path / name
        rows = "\n".join(f"{a:.4f},{b:.4f},{c:.4f},{d}" for a, b, c, d in zip(t, x, y, column))
        path.write_text(f"t,x,y,{name.split('.')[0]}\n{rows}\n")
        return path

    options = ["--length-unit", "mm", "--time-unit", "ms", "--width", "0.09", "--height",
               "0.95", "--resample", "0.005", "--max-gap", "0.02"]
    out = tmp_path / "p.h5"
    assert main(["import", str(write("tid.csv", tracer)), "-o", str(out), *options]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "column 'tid' seems to number the tracers (2 whole" in err
    assert "name the column id, tracer, label or track" in err and not out.exists()
    assert main(["import", str(write("tracer.csv", tracer)), "-o", str(out), *options]) == 0
    with Trajectories(out) as run:
        assert run.n_particles == 2
    one = write("detector.csv", detector)
    keep = tracer == 0
    one.write_text("\n".join(line for line, k in zip(one.read_text().splitlines(),
                                                     [True, *keep]) if k) + "\n")
    assert main(["import", str(one), "-o", str(tmp_path / "one.h5"), *options]) == 0
    assert "not used: 'detector'" in capsys.readouterr().err

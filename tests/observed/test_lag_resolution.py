"""A lag that cannot tell a periodic riser's passes: particles that move half the riser's
height or more within it are refused in one line naming a lag that can, for the model's
transitions and for residences observed on frames one lag apart."""

import numpy as np
import pytest

from cfbmarkov.cli import main
from cfbmarkov.errors import InputError
from cfbmarkov.observed.lag_resolution import check_lag_resolves_passes
from cfbmarkov.observed.residence import residence_times
from cfbmarkov.trajectories import Trajectories
from cfbmarkov.trajectory_writer import write_trajectories

H, DT = 0.95, 0.025


def _riser(path, speeds, frames=81, dt=DT):
    """Particles rising at constant ``speeds`` (m/s) through a 0.09 x 0.95 m periodic riser,
    their laps counted from the unwrapped heights (as an import of unwrapped coordinates
    does)."""
    times = dt * np.arange(frames)
    speeds = np.asarray(speeds, dtype=float)
    unwrapped = 0.01 + np.outer(times, speeds) + np.linspace(0, 0.5, speeds.size)
    x = np.broadcast_to(np.linspace(0.01, 0.08, speeds.size), unwrapped.shape)
    positions = np.stack([x, np.mod(unwrapped, H)], axis=-1)
    return write_trajectories(path, times, positions, width=0.09, height=H,
                              laps=np.floor_divide(unwrapped, H).astype(np.int64))


def test_the_kernel_counts_the_passes_the_heights_misread():
    """Moves of 0.15 m a frame: over 4 frames (0.6 m) the minimal image misreads every move
    (a rise through the top reads as a fall, a rise of 0.6 m as a pass down) and the lag is
    refused, naming 3 frames (0.45 m) as the longest; over 3 frames nothing is misread."""
    times = DT * np.arange(20)
    unwrapped = 6.0 * times[:, None] + np.array([0.0, 0.3])
    laps, heights = np.floor_divide(unwrapped, H), np.mod(unwrapped, H)
    check_lag_resolves_passes(heights, laps, 3, H, DT)
    passes = int(np.count_nonzero(laps[4:] != laps[:-4]))
    with pytest.raises(InputError, match=rf"run\.h5: at a lag of 0\.1 s the heights one lag "
                                         rf"apart read 32 passes .* wrong .* against the {passes} "
                                         r"that the file's laps count, in 32 "
                                         r"particle moves: .*up to 0\.6 m; give a lag of at "
                                         r"most 0\.075 s \(--lag\)"):
        check_lag_resolves_passes(heights, laps, 4, H, DT, "run.h5")
    # an absent particle (NaN) is no move
    heights[:, 1] = np.nan
    with pytest.raises(InputError, match="in 16 particle moves"):
        check_lag_resolves_passes(heights, laps, 4, H, DT)


def test_a_few_misread_passes_below_the_tolerance_pass():
    """One misread move among more than a thousand passes (below TOLERANCE of them) is
    accepted; two are refused."""
    from cfbmarkov.observed.lag_resolution import TOLERANCE

    n = int(1.5 / TOLERANCE)
    heights = np.tile([[0.9], [0.1]], (1, n))     # every particle passes the top once
    laps = np.tile([[0], [1]], (1, n))
    heights[1, 0], laps[1, 0] = 0.6, 1            # a rise of 0.65 m through the top
    check_lag_resolves_passes(heights, laps, 1, H, DT)
    heights[1, 1], laps[1, 1] = 0.6, 1
    with pytest.raises(InputError, match=f"read 2 passes .* wrong .* against the {n} "):
        check_lag_resolves_passes(heights, laps, 1, H, DT)


def test_fit_refuses_a_lag_that_cannot_tell_the_passes(tmp_path, capsys):
    """The minimal image over 0.1 s takes a rise of 0.6 m through the top for a fall of
    0.35 m: the fit is refused in one line with the lag that works, and at that lag every
    pass is counted upward, as the file's laps say."""
    run = _riser(tmp_path / "run.h5", [6.0, 5.5, 6.0, 5.0])
    assert main(["fit", str(run), "--cells", "2x4", "--lag", "0.1", "--window", "0:2", "-o",
                 str(tmp_path / "m.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "give a lag of at most 0.075 s (--lag)" in err
    assert not (tmp_path / "m.h5").exists()
    assert main(["fit", str(run), "--cells", "2x4", "--lag", "0.075", "--window", "0:2", "--resamples", "0",
                 "--no-adequacy", "-o", str(tmp_path / "m.h5")]) == 0
    out = capsys.readouterr().out
    assert "passes through the periodic boundary: " in out and ", 0 down" in out


def test_frames_too_far_apart_are_refused_with_the_frame_interval_that_works(tmp_path,
                                                                             capsys):
    """Laps from unwrapped coordinates count passes that frames 0.1 s apart cannot show to
    the states: a lag of one frame is refused, naming the frame interval that would do."""
    run = _riser(tmp_path / "run.h5", [6.0, 9.5], frames=11, dt=0.1)
    assert main(["fit", str(run), "--cells", "2x4", "--lag", "0.1", "--window", "0:1", "-o",
                 str(tmp_path / "m.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the file's frames, 0.1 s apart, are too far apart" in err
    assert "write frames at most 0.05 s apart" in err
    # the other cause is named beside it: laps that contradict the positions
    assert "the file's laps contradict its positions: laps written as zeros" in err


def test_residences_shorter_than_the_lag_are_refused(tmp_path):
    """Frames 0.025 s apart taken every 8 (0.2 s): a particle rising at 9.5 m/s passes the
    top twice between two of them, a residence that would be recorded as zero; refused.
    Every frame: the residences are H / v."""
    run = _riser(tmp_path / "run.h5", [9.5, 9.5])
    with Trajectories(run) as t:
        with pytest.raises(InputError, match=r"at a lag of 0\.2 s, \d+ of \d+ residences are "
                                             r"shorter than the lag"):
            residence_times(t, (0.0, 2.0), use_events=False, lag_frames=8)
        samples = residence_times(t, (0.0, 2.0), use_events=False).samples
    assert samples.min() > 0 and abs(np.median(samples) - H / 9.5) <= DT


def test_a_move_over_an_absence_is_not_read_against_laps_that_miss_its_pass(tmp_path):
    """Particles rising 0.05 m a frame, each missing from one frame in five, written
    without laps (counted from the heights between the frames present, carried on across an
    absence): a pass made while a particle was away is in no lap counter, so over a lag of
    four frames the move across it was read as a misread pass and the lag refused ("moves
    half the riser's height ... up to 0.9 m"). Those moves are left out; the same moves seen
    whole are still read and counted."""
    from cfbmarkov.observed.lag_resolution import read_passes

    frames, n = 200, 12
    times = DT * np.arange(frames)
    unwrapped = 0.01 + 2.0 * times[:, None] + np.linspace(0, 0.9, n)
    heights = np.mod(unwrapped, H)
    present = np.ones((frames, n), bool)
    for p in range(n):
        present[5 + p % 5::5, p] = False
    positions = np.stack([np.full((frames, n), 0.05), heights], axis=-1)
    positions[~present] = np.nan
    path = write_trajectories(tmp_path / "gaps.h5", times, positions, width=0.09, height=H,
                              present=present)
    with Trajectories(path) as traj:
        laps = traj.laps(slice(0, frames))
    vertical = np.where(present, heights, np.nan)
    reading = read_passes(vertical, laps, 4, H, DT)
    assert reading.misread == 0
    whole = int(sum(1 for t in range(frames - 4) for p in range(n)
                    if present[t:t + 5, p].all()))
    assert reading.moves == whole > 0
    assert reading.passes > 0
    assert main(["fit", str(path), "--cells", "2x8", "--lag", "0.1", "--window", "0:4.9",
                 "--resamples", "0", "-o", str(tmp_path / "m.h5"), "-q"]) == 0

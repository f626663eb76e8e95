"""The CFD-DEM's progress bar (simulate.progress)."""

from cfbmarkov.simulate.progress import Progress


def test_the_bar_never_passes_its_total_nor_shows_a_negative_time_left(capsys):
    """Three frames of 0.1 s sum to 0.30000000000000004 in floats: the bar stops at its
    total of 0.3 s (tqdm showed the ulp beyond it as "<-00:00" left)."""
    progress = Progress("bar", 0.0, 0.3, 10)
    for _ in range(3):
        progress.update(0.1, 100)
    assert progress.bar.n <= progress.bar.total
    assert progress.bar.n == progress.bar.total or progress.bar.total - progress.bar.n < 1e-12
    progress.bar.refresh()
    progress.close(finished=True)
    assert "-00:00" not in capsys.readouterr().err

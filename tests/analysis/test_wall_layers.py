"""The wall/core figures of a reproduction's report: each wall layer is the outer sixth of
the riser's width whatever the number of profile bins (the paper's 9 gas columns give 18
bins, three to a layer; the quick scale's 4 columns give 8 bins, a layer then ends a third
of the way into the second bin)."""

import numpy as np
import pytest

from cfbmarkov.analysis.reproduction import wall_core_contrast, wall_zone_weights


@pytest.mark.parametrize("bins", [1, 4, 8, 18, 25])
def test_layers_are_a_sixth_of_the_width_and_partition_every_bin(bins):
    left, core, right = wall_zone_weights(bins)
    assert np.allclose(left + core + right, 1.0)
    assert left.sum() / bins == pytest.approx(1 / 6) and right.sum() / bins == pytest.approx(1 / 6)
    assert np.allclose(left, right[::-1])


def test_wall_and_core_means_integrate_the_profile_over_the_sixths():
    """A profile of 8 bins whose values equal the bins' centres x / W: the mean over the
    outer sixths is that of a step function sampled finely, not of the outer bins."""
    bins = 8
    centres = (np.arange(bins) + 0.5) / bins
    fraction = 0.1 + 0.2 * np.abs(centres - 0.5)
    velocity = np.where(np.arange(bins) == 2, np.nan, 3.0 * centres)   # one empty bin
    fine = (np.arange(48000) + 0.5) / 48000
    step = np.minimum((fine * bins).astype(int), bins - 1)
    wall_zone = (fine < 1 / 6) | (fine > 5 / 6)
    wall, core, v_wall, v_core = wall_core_contrast(fraction, velocity)
    assert wall == pytest.approx(fraction[step][wall_zone].mean(), rel=1e-9)
    assert core == pytest.approx(fraction[step][~wall_zone].mean(), rel=1e-9)
    finite = np.isfinite(velocity[step])
    assert v_wall == pytest.approx(velocity[step][wall_zone & finite].mean(), rel=1e-9)
    assert v_core == pytest.approx(velocity[step][~wall_zone & finite].mean(), rel=1e-9)
    # the outer bins alone (an eighth of the width each) are not the layers
    assert wall != pytest.approx(np.r_[fraction[:1], fraction[-1:]].mean(), rel=1e-3)


def test_eighteen_bins_take_three_whole_bins_a_layer():
    fraction = np.arange(18.0)
    wall, core, _, _ = wall_core_contrast(fraction, fraction)
    assert wall == pytest.approx(np.r_[fraction[:3], fraction[-3:]].mean())
    assert core == pytest.approx(fraction[3:-3].mean())

"""Warnings on an imported file whose sizes suggest a unit mistake: a riser kilometres
high, particles crowded into a sliver of the riser, frames microseconds apart. The import
itself stands (the sizes may be meant); the lines say what to check and how to fix it."""

from __future__ import annotations

import numpy as np

#: a riser's height (m) outside which the lengths are likely not in metres
HEIGHT_RANGE = (0.01, 100.0)
#: the share of the riser's height below which the particles' span suggests other units
SPAN_SHARE = 0.01
#: a frame interval (s) below which the times are likely not in seconds
SHORTEST_FRAME_INTERVAL = 1e-5
#: frames read to measure the particles' span (the first, the last and some between)
SAMPLED_FRAMES = 5


def unit_warnings(traj) -> list[str]:
    """The unit warnings of an imported trajectory file.

    Parameters
    ----------
    traj : Trajectories
        An open trajectory file.

    Returns
    -------
    list of str
        One line each: a riser height outside :data:`HEIGHT_RANGE`, particles whose heights
        over a few frames (:data:`SAMPLED_FRAMES`, first to last) span less than
        :data:`SPAN_SHARE` of the riser's height, or frames less than
        :data:`SHORTEST_FRAME_INTERVAL` apart.
    """
    lines = []
    height, width = traj.height, traj.width
    low, high = HEIGHT_RANGE
    if not low <= height <= high:
        lines.append(f"the riser is {height:g} m high and {width:g} m wide: lengths are in "
                     "metres (CSV: --length-unit for the positions' unit; --width, --height and "
                     "--region in the source's own units); check the units if that is not "
                     "the riser")
    frames = np.unique(np.linspace(0, traj.n_frames - 1, SAMPLED_FRAMES).round().astype(int))
    heights = np.concatenate([traj.positions(int(k))[:, 1] for k in frames])
    heights = heights[np.isfinite(heights)]
    if heights.size > 1:
        span = float(heights.max() - heights.min())
        if span < SPAN_SHARE * height:
            lines.append(f"the particles' heights span {span:.3g} m of the riser's {height:g} m "
                         f"(in {frames.size} frames from the first to the last): the positions' "
                         "unit and the riser's may differ (CSV: --length-unit; --width, --height "
                         "and --region are in the source's own units)")
    interval = traj.frame_interval
    if np.isfinite(interval) and 0 < interval < SHORTEST_FRAME_INTERVAL:
        lines.append(f"frames {interval:g} s apart: times are in seconds (CSV: --time-unit ms "
                     "for milliseconds; dumps: --time-step in s); check the times if that is "
                     "not the sampling")
    return lines


__all__ = ["unit_warnings"]

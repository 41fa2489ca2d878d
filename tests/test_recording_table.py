"""The table of plots: each declared once, documented in docs/recordings.md, shown in one view."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun.blueprint as rrb

from pickplace.errors import InvalidInputError
from pickplace.record.blueprint import LIMIT_LINES, PLOTS, LimitLines, Plot, build_blueprint
from pickplace.sim.ticklog import TickLog
from pickplace.world.scene import Scene

DOC = Path(__file__).resolve().parent.parent / "docs" / "recordings.md"
TABLE_PATHS = [s.path for s in (*PLOTS, *LIMIT_LINES)]


def documented_entity_paths() -> set[str]:
    """Every entity path named in the first cell of the entity table of docs/recordings.md."""
    text = DOC.read_text()
    section = text.split("## Entity paths", 1)[1].split("\n## ", 1)[0]
    paths: set[str] = set()
    for line in section.splitlines():
        if line.startswith("| `"):
            first_cell = line.split(" | ", 1)[0]
            paths.update(re.findall(r"`([^`]+)`", first_cell))
    return paths


def test_every_plot_is_in_the_documented_entity_table_and_vice_versa() -> None:
    documented = {p for p in documented_entity_paths() if p.startswith("plots/")}
    assert documented == set(TABLE_PATHS)


def test_the_documented_table_is_found() -> None:
    paths = documented_entity_paths()
    assert {"world", "events", "summary"} <= paths


def test_each_entity_path_is_declared_once() -> None:
    assert len(TABLE_PATHS) == len(set(TABLE_PATHS))


def _views(node: Any, tab: str | None = None) -> list[tuple[str | None, Any]]:
    """(tab name, view) of every time series view under ``node``."""
    if isinstance(node, rrb.TimeSeriesView):
        return [(tab, node)]
    out = []
    for child in getattr(node, "contents", None) or []:
        name = node.name if isinstance(node, rrb.Tabs) else tab
        out += _views(child, name)
    return out


def test_each_plot_has_one_view_in_its_tab_that_shows_it_and_its_limit_lines() -> None:
    views = _views(build_blueprint().root_container)
    assert len(views) == len(PLOTS)
    for plot, (tab, view) in zip(PLOTS, views, strict=True):
        assert (tab, view.name) == (plot.tab, plot.title)
        if plot.limits is None:
            assert (view.origin, view.contents) == (plot.path, "$origin/**")
        else:
            assert view.contents == [plot.path, plot.limits.path]


def test_series_names_match_the_width_of_the_values(scene: Scene) -> None:
    ticks = 3
    log = TickLog(scene, ticks, 0.01)
    log.derive(0, ticks)
    for plot in PLOTS:
        values = np.asarray(plot.values(log, slice(0, ticks)))
        assert values.shape[0] == ticks, plot.path
        width = 1 if values.ndim == 1 else values.shape[1]
        assert len(plot.series_names(scene)) == width, plot.path
    for lines in LIMIT_LINES:
        assert len(lines.series_names(scene)) == len(lines.values(scene)), lines.path


def test_a_plot_is_validated_when_declared() -> None:
    def values(log: TickLog, rows: slice) -> np.ndarray:
        return log.q[rows]

    kw: dict[str, Any] = {"tab": "t", "title": "t", "names": ("a",), "values": values}
    with pytest.raises(InvalidInputError, match="starts with 'plots/'"):
        Plot(path="world/x", **kw)
    with pytest.raises(InvalidInputError, match="low < high"):
        Plot(path="plots/x", y_range=(1.0, 0.0), **kw)
    with pytest.raises(InvalidInputError, match="line width"):
        LimitLines(path="plots/x", names=("a",), values=lambda sc: [0.0], width=0.0)

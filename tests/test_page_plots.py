"""The student page's live plots in a real headless Chromium: pause, zoom and CSV download."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from page_helpers import (
    Bridge,
    driving_page,
    needs_browser,
    page_url,
)

from server_process import ServerProcess

HISTORY_PLOTTED_S = 20.0
"""Seconds the live plots show (state.js HISTORY_S)."""


@needs_browser
def test_plots_pause_zoom_and_save_their_samples_as_csv(server: ServerProcess, bridge: Bridge,
                                                     browser: Any) -> None:
    with driving_page(browser, bridge, page_url(server),
                      viewport={"width": 1280, "height": 860}) as (page, log):
        plotted = "window.websim.plots.charts[0].plot.data[0].length"
        page.wait_for_function(f"{plotted} > 10", timeout=10000)
        page.click("#plots-tools button:text('Pause')")
        frozen = page.evaluate(plotted)
        samples = page.evaluate("window.websim.state.history.t.length")
        page.wait_for_function(f"window.websim.state.history.t.length > {samples + 10}",
                               timeout=10000)
        assert page.evaluate(plotted) == frozen  # paused: the samples go on, the chart not
        chart = page.locator("#plots .plot .u-over").first  # uPlot's drag-to-zoom surface
        box = chart.bounding_box()
        assert box is not None
        page.mouse.move(box["x"] + 0.5 * box["width"], box["y"] + box["height"] / 2)
        page.mouse.down()
        page.mouse.move(box["x"] + 0.9 * box["width"], box["y"] + box["height"] / 2, steps=5)
        page.mouse.up()
        x_min, x_max = page.evaluate("[window.websim.plots.charts[0].plot.scales.x.min, "
                                     "window.websim.plots.charts[0].plot.scales.x.max]")
        assert x_max - x_min < 0.6 * HISTORY_PLOTTED_S, (x_min, x_max)  # zoomed: 40 % of it
        assert x_min > -0.6 * HISTORY_PLOTTED_S, (x_min, x_max)
        with page.expect_download() as download:
            page.click("#plots-tools button:text('CSV')")
        text = Path(download.value.path()).read_text()
        rows = text.strip().splitlines()
        assert rows[0].startswith("stamp_s,v_cmd_mps,v_mps")
        assert len(rows) > samples
        page.click("#plots-tools button:text('Resume')")
        page.wait_for_function(f"{plotted} > {frozen}", timeout=10000)
        assert log.page_errors == []

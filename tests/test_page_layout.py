"""The student page on a 1280 x 800 laptop in a real headless Chromium: the whole arena and
the readouts on the first screen, velocity plots that fill their card and are tall enough to
read, and a step window in which the dynamic mode's ramp (0.14 s to 90 %: docs/assignments.md)
is tens of pixels wide, live, without pausing or zooming.
"""

from __future__ import annotations

from typing import Any

from page_helpers import (
    Bridge,
    driving_page,
    needs_browser,
    page_url,
    reset_robot,
    screenshot,
    speed_of,
    wait_until_still,
)

from server_process import ServerProcess, wait_for

LAPTOP = {"width": 1280, "height": 800}
"""A common laptop's screen in CSS px."""
MIN_PLOT_HEIGHT_PX = 150.0
"""The plotting area (uPlot's .u-over: the axes left out) at least this high."""
MIN_RAMP_PX = 25.0
"""The dynamic mode's 0.14 s ramp at least this wide in the step window."""

GEOMETRY_JS = """() => {
  const box = (el) => el.getBoundingClientRect();
  const view = window.websim.view;
  const b = window.websim.state.worldBounds;
  const top = box(document.querySelector('#view')).top;
  const card = document.querySelector('#plots');
  const style = getComputedStyle(card);
  return {
    wallBottom: top + view.worldToScreen(0, b.minY)[1],
    readoutsBottom: box(document.querySelector('#readouts')).bottom,
    plotHeights: [...card.querySelectorAll('.u-over')].map((el) => box(el).height),
    figuresWidth: [...card.querySelectorAll('.plot')].reduce((w, el) => w + box(el).width, 0)
      + parseFloat(style.columnGap) * (card.querySelectorAll('.plot').length - 1),
    cardWidth: box(card).width,
    overWidth: box(card.querySelector('.u-over')).width,
  };
}"""


def set_mode(server: ServerProcess, mode: str) -> None:
    admin = Bridge(server.admin_ws_url)
    try:
        reply = admin.call("/virtual_robot/set_parameters", {"parameters": [
            {"name": "mode", "value": {"type": 4, "string_value": mode}}]})
        assert reply["result"] is True and reply["values"]["results"][0]["successful"], reply
    finally:
        admin.close()


@needs_browser
def test_a_laptop_shows_the_arena_the_readouts_and_readable_plots(server: ServerProcess,
                                                                 bridge: Bridge,
                                                                 browser: Any) -> None:
    with driving_page(browser, bridge, page_url(server), viewport=LAPTOP) as (page, log):
        page.wait_for_function("window.websim.state.worldBounds !== null", timeout=10000)
        layout = page.evaluate(GEOMETRY_JS)
        screenshot(page, "laptop-first-screen.png", full_page=False)
        assert layout["wallBottom"] <= LAPTOP["height"], layout  # the whole arena
        assert layout["readoutsBottom"] <= LAPTOP["height"], layout
        assert min(layout["plotHeights"]) >= MIN_PLOT_HEIGHT_PX, layout
        assert layout["figuresWidth"] >= 0.98 * layout["cardWidth"], layout  # they fill it

        set_mode(server, "dynamic")
        reset_robot(bridge)  # a new mode takes effect at the reset
        try:
            page.click("#plots-tools button[data-window=step]")
            page.keyboard.down("ArrowUp")
            wait_for(lambda: speed_of(bridge.messages("/odom")[-1]) > 0.2, what="the ramp up")
            page.wait_for_timeout(1000)  # the step window: 0.8 s after the step
            page.keyboard.up("ArrowUp")
            wait_until_still(bridge)
            page.wait_for_timeout(500)  # a steady command before the next step
            page.keyboard.down("ArrowUp")  # again: the last step is this one
            page.wait_for_timeout(1000)
            chart = page.evaluate("""() => {
              const { plot } = window.websim.plots.charts[0];
              return {x: plot.data[0], cmd: plot.data[1], truth: plot.data[2],
                      min: plot.scales.x.min, max: plot.scales.x.max};
            }""")
            screenshot(page, "laptop-step-window.png")
            page.keyboard.up("ArrowUp")
            wait_until_still(bridge)
        finally:
            set_mode(server, "kinematic")
            reset_robot(bridge)
        assert log.page_errors == []
    assert (chart["min"], chart["max"]) == (-0.2, 0.8), chart  # 0 s is the step
    target = max(chart["cmd"])
    shown = [(x, v) for x, v in zip(chart["x"], chart["truth"], strict=True)
             if x >= chart["min"] and v is not None]
    rise_s = next(x for x, v in shown if v >= 0.9 * target)
    starts_s = max(x for x, v in shown if v <= 0.1 * target and x < rise_s)
    # The true speed ramps (2.5 m/s^2 at 1.2 kg) after the command's way to the robot.
    assert 0.05 <= rise_s - starts_s <= 0.2 and rise_s <= 0.4, shown[:10]
    px_per_s = layout["overWidth"] / (chart["max"] - chart["min"])
    assert (rise_s - starts_s) * px_per_s >= MIN_RAMP_PX, (rise_s, starts_s, px_per_s)

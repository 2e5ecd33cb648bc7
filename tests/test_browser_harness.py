"""The browser harness (tests/browser.py) against truths it does not compute itself.

A plotly page whose only red is its 3-D markers and whose only strong blue is its mesh must
show both colours in the plot area; pages that load from a port nothing listens on must be
reported as having made that request; a self-contained page as having made none.
"""
import socket

import numpy as np
import plotly.graph_objects as go
import plotly.io as pio
import pytest
from PIL import Image

from browser import chromium, requires_chromium

pytestmark = requires_chromium



def _closed_port():
    """A local port nothing listens on: bound by the OS, then released (connection refused)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# Port 9 (discard) is refused by Chromium itself (ERR_UNSAFE_PORT) before any connection is
# tried; an ephemeral closed port is really tried and refused by the OS.  Both are requests.
DEAD = [pytest.param("http://127.0.0.1:9", id="port-9"),
        pytest.param(f"http://127.0.0.1:{_closed_port()}", id="closed-port")]


@pytest.fixture(scope="module")
def browser():
    with chromium(width=1000, height=700) as b:
        yield b


def _page(path, body):
    path.write_text(f"<!doctype html><html><head><meta charset='utf-8'></head><body>{body}</body></html>")
    return path


def _plot(path):
    """A self-contained plotly page: red scatter3d markers and a blue mesh3d tetrahedron."""
    fig = go.Figure([
        go.Scatter3d(x=[0, 1, 2, 0], y=[0, 1, 0, 2], z=[0, 1, 2, 1], mode="markers",
                     marker=dict(size=14, color="rgb(255,0,0)")),
        go.Mesh3d(x=[3, 4, 3, 3], y=[3, 3, 4, 3], z=[0, 0, 0, 1], i=[0, 0, 0, 1], j=[1, 1, 2, 2],
                  k=[2, 3, 3, 3], color="rgb(0,0,255)", flatshading=True),
    ])
    fig.update_layout(showlegend=False, margin=dict(l=0, r=0, t=0, b=0))
    pio.write_html(fig, path, include_plotlyjs=True, full_html=True,
                   post_script="window.plotReady = true;")
    return path


def test_self_contained_plotly_page_renders_webgl_and_makes_no_request(browser, tmp_path):
    seconds = browser.open(_plot(tmp_path / "plot.html"), wait_for_js="window.plotReady === true")
    assert 0 < seconds < 60
    assert browser.requests() == []
    assert browser.console_errors() == []
    assert browser.js("document.querySelectorAll('.gl-container canvas').length") >= 1

    shot = browser.screenshot(tmp_path / "plot.png")
    pixels = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert pixels.shape == (700, 1000, 3)
    left, top, right, bottom = browser.rect(".js-plotly-plot")
    area = pixels[max(top, 0):bottom, max(left, 0):right]
    assert area.size > 0.5 * pixels.size
    r, g, b = area[..., 0], area[..., 1], area[..., 2]
    assert len(np.unique(area.reshape(-1, 3), axis=0)) > 50       # not blank
    assert ((r > 200) & (g < 60) & (b < 60)).sum() > 300           # the scatter3d markers
    assert ((b > r + 80) & (b > g + 80)).sum() > 300               # the mesh3d surface


@pytest.mark.parametrize("dead", DEAD)
def test_image_from_a_dead_port_is_reported(browser, tmp_path, dead):
    page = _page(tmp_path / "img.html", f'<p>x</p><img src="{dead}/x.png">')
    browser.open(page)
    assert browser.requests() == [f"{dead}/x.png"]


@pytest.mark.parametrize("dead", DEAD)
def test_fetch_to_a_dead_port_is_reported(browser, tmp_path, dead):
    page = _page(tmp_path / "fetch.html",
                 f"<script>fetch('{dead}/api').catch(() => 0).finally(() => {{ window.settled = true; }});</script>")
    browser.open(page, wait_for_js="window.settled === true")
    assert browser.requests() == [f"{dead}/api"]


def test_plain_page_makes_no_request_and_js_evaluates(browser, tmp_path):
    page = _page(tmp_path / "plain.html", "<p id='p'>hello</p><img src='data:image/gif;base64,"
                 "R0lGODlhAQABAAAAACw='>")
    browser.open(page)
    assert browser.requests() == []
    assert browser.js("document.getElementById('p').textContent + arguments[0]", "!") == "hello!"
    assert browser.js("Promise.resolve(6 * 7)") == 42


def test_a_page_that_never_gets_ready_fails_clearly(browser, tmp_path):
    page = _page(tmp_path / "never.html", "<p>never ready</p>")
    with pytest.raises(AssertionError, match=r"never\.html was not ready within 1 s.*window\.neverReady"):
        browser.open(page, wait_for_js="window.neverReady === true", timeout=1)
    with pytest.raises(AssertionError, match="no such file"):
        browser.open(tmp_path / "absent.html")


def test_timings_are_the_pages_own_clock(browser, tmp_path):
    """The page's paint entries, its largest paint (here its only text) and its marks, in seconds."""
    page = _page(tmp_path / "marks.html", "<p>painted</p><script>performance.mark('start'); requestAnimationFrame("
                 "() => setTimeout(() => { performance.mark('after-paint'); window.marked = true; }))</script>")
    browser.open(page, wait_for_js="window.marked === true")
    clock = browser.timings()
    assert 0 < clock["start"] < clock["after-paint"]
    assert 0 < clock["first-paint"] <= clock["first-contentful-paint"]
    assert clock["largest-contentful-paint"] > 0


def test_scripts_off_runs_none_of_the_pages_scripts(browser, tmp_path):
    page = _page(tmp_path / "script.html", "<p id='p'>html</p><script>document.getElementById('p').textContent = 'js'"
                 "</script>")
    with browser.scripts_off():
        browser.open(page)
        assert browser.js("document.getElementById('p').textContent") == "html"
        shot = np.asarray(Image.open(browser.screenshot(tmp_path / "off.png")).convert("L"))
        assert shot.min() < 100                                            # the text is drawn
        with pytest.raises(AssertionError, match="scripts_off"):
            browser.timings()
    browser.open(page)
    assert browser.js("document.getElementById('p').textContent") == "js"

"""Driving real headless Chromium from tests (a harness, not a test file).

Debian's packages `chromium` and `chromium-driver` (installed by `make test`, target
`chromium`) are driven through selenium 4.  Selenium Manager is never used: the driver
path is given to `Service`, so nothing is downloaded.

    from browser import chromium, requires_chromium

    @requires_chromium
    def test_report(tmp_path):
        with chromium() as b:
            seconds = b.open(tmp_path / "report.html", wait_for_js="window.breastplanReady === true")
            assert b.requests() == []
            shown = b.timings()["breastplan-shown"]      # s from navigation start, the browser's clock
            b.screenshot(tmp_path / "report.png")
            with b.scripts_off():                        # as with JavaScript off
                b.open(tmp_path / "report.html")

Timeouts here detect failures (a page that never becomes ready); they are not speed
assertions.  The viewport is exactly `width` x `height` CSS pixels at device pixel ratio 1,
so rectangles from `rect()` index the screenshot's pixels directly.
"""
from __future__ import annotations

import json
import os
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"

# --use-angle=swiftshader --enable-unsafe-swiftshader: WebGL (plotly's 3-D scenes) through
# ANGLE on the SwiftShader software Vulkan that Debian's chromium ships in /usr/lib/chromium;
# --disable-gpu keeps Chromium off any real GPU, so results do not depend on the machine.
# No --allow-file-access-from-files: a report must work as a user's browser opens it.
FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
)

# Milliseconds of the page's paint entries, largest contentful paint and marks. Paints are reported
# when the frame is presented, some time after it is drawn: an observer gets those already reported
# at once (buffered) and waits up to 1 s for first-contentful- and largest-contentful-paint.
_TIMINGS = """new Promise(done => {
  const out = {};
  const finish = () => {
    for (const e of performance.getEntriesByType('mark')) out[e.name] = e.startTime;
    done(out);
  };
  const seen = new PerformanceObserver(list => {
    for (const e of list.getEntries()) out[e.entryType === 'paint' ? e.name : e.entryType] = e.startTime;
    if ('first-contentful-paint' in out && 'largest-contentful-paint' in out) finish();
  });
  for (const type of ['paint', 'largest-contentful-paint'])
    if (PerformanceObserver.supportedEntryTypes.includes(type)) seen.observe({type, buffered: true});
  setTimeout(finish, 1000);
})"""

# Requests that are not network traffic: inline data, blobs made by the page, blank frames.
_NOT_NETWORK = ("data:", "blob:", "about:")


def missing_chromium() -> str | None:
    """Why the browser tests cannot run here, or None when they can."""
    absent = [p for p in (CHROMIUM, CHROMEDRIVER) if not os.access(p, os.X_OK)]
    if absent:
        return (f"{' and '.join(absent)} not found: install Debian's chromium and chromium-driver "
                "(`make chromium` as root, or sudo apt-get install chromium chromium-driver)")
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed: pip install -e '.[test]'"
    return None


def skip_without_chromium() -> None:
    """Skip the calling test, with the reason, when Chromium or chromedriver is absent."""
    reason = missing_chromium()
    if reason:
        pytest.skip(reason)


#: Marker form of `skip_without_chromium`: `@requires_chromium` on a test, or `pytestmark = requires_chromium`.
requires_chromium = pytest.mark.skipif(missing_chromium() is not None, reason=missing_chromium() or "")


def _strip_fragment(url: str) -> str:
    return url.split("#", 1)[0]


class Browser:
    """One headless Chromium window.  `driver` is the selenium WebDriver, for anything else."""

    def __init__(self, driver, width: int, height: int):
        self.driver = driver
        self.width, self.height = width, height
        self._page: str | None = None      # file:// URL of the page last opened
        self._logged: list[str] = []        # requests from the performance log since then
        self._console: list[str] = []       # SEVERE console messages since then
        self._scripts = True                # whether pages run their scripts (and timers, frame callbacks)

    # -- loading -------------------------------------------------------------------------
    def open(self, path, wait_for_js: str | None = None, *,
             ready: str = "document.readyState === 'complete'", timeout: float = 60.0) -> float:
        """Load the local file `path`; seconds until `ready` (and `wait_for_js`, if given) hold.

        Both are JavaScript expressions, polled until truthy; an expression that throws counts
        as not yet true.  Raises AssertionError when the file is absent or the page is not
        ready within `timeout` seconds (failure detection, not a speed assertion).
        Resets `requests()` and `console_errors()` to this page.
        """
        from selenium.common.exceptions import TimeoutException

        path = Path(path).resolve()
        assert path.is_file(), f"cannot open {path} in the browser: no such file"
        url = path.as_uri()
        self._drain()
        self._page, self._logged, self._console = url, [], []
        predicate = ready if not wait_for_js else f"({ready}) && ({wait_for_js})"
        probe = ("try { return [!!(%s), null]; } catch (e) { return [false, String(e)]; }" % predicate)
        self.driver.set_page_load_timeout(timeout)
        start = time.perf_counter()
        try:
            self.driver.get(url)
        except TimeoutException:
            raise AssertionError(f"{url} did not finish loading within {timeout:g} s") from None
        deadline = start + timeout
        while True:
            ok, error = self.driver.execute_script(probe)
            if ok:
                return time.perf_counter() - start
            if time.perf_counter() > deadline:
                detail = f" (last evaluation threw {error})" if error else ""
                raise AssertionError(f"{url} was not ready within {timeout:g} s: "
                                     f"`{predicate}` never became true{detail}")
            time.sleep(0.05)

    # -- what the page did ---------------------------------------------------------------
    def _drain(self) -> None:
        """Move the browser's buffered logs (get_log empties them) into this object."""
        for entry in self.driver.get_log("performance"):
            message = json.loads(entry["message"])["message"]
            method, params = message.get("method"), message.get("params", {})
            if method == "Network.requestWillBeSent":
                self._logged.append(params["request"]["url"])
            elif method == "Network.webSocketCreated":
                self._logged.append(params["url"])
        for entry in self.driver.get_log("browser"):
            if entry.get("level") == "SEVERE":
                self._console.append(entry["message"])

    def requests(self) -> list[str]:
        """URLs of every request the page opened last made, other than its own file:// URL.

        From Chrome's performance log (`Network.requestWillBeSent`, `Network.webSocketCreated`)
        and the page's `performance.getEntriesByType('resource')`, in order, without repeats;
        data:, blob: and about: URLs are not network traffic and are left out.  A request the
        page has not issued yet (e.g. from a timer) is not seen: wait for it first.
        """
        assert self._page is not None, "requests(): no page opened yet"
        self._drain()
        resources = self.driver.execute_script(
            "return performance.getEntriesByType('resource').map(e => e.name)")
        seen, out = set(), []
        for url in [*self._logged, *resources]:
            if url in seen or _strip_fragment(url) == self._page or url.startswith(_NOT_NETWORK):
                continue
            seen.add(url)
            out.append(url)
        return out

    def console_errors(self) -> list[str]:
        """SEVERE console messages (uncaught exceptions, failed loads) of the page opened last."""
        self._drain()
        return list(self._console)

    @contextmanager
    def scripts_off(self) -> Iterator["Browser"]:
        """Pages opened inside run none of their own scripts, as in a browser with JavaScript off;
        the harness's own calls (`js`, `rect`, `screenshot`) still work."""
        self.driver.execute_cdp_cmd("Emulation.setScriptExecutionDisabled", {"value": True})
        self._scripts = False
        try:
            yield self
        finally:
            self.driver.execute_cdp_cmd("Emulation.setScriptExecutionDisabled", {"value": False})
            self._scripts = True

    def timings(self) -> dict[str, float]:
        """Seconds from navigation start, by the browser's own clock, of the page opened last: its
        paint entries (first-paint, first-contentful-paint), its largest-contentful-paint (when it
        had one: an image or text, not a WebGL canvas; waited for up to 1 s) and its performance
        marks, by name.
        Not inside `scripts_off` (it needs the page's timers)."""
        assert self._scripts, "timings(): the page's timers do not run inside scripts_off()"
        return {name: ms / 1e3 for name, ms in self.js(_TIMINGS).items()}

    # -- looking at it ---------------------------------------------------------------------
    def js(self, expr: str, *args):
        """Value of the JavaScript expression `expr` (`arguments[i]` are `args`); a Promise is awaited."""
        return self.driver.execute_script(f"return ({expr});", *args)

    def rect(self, selector: str) -> tuple[int, int, int, int]:
        """(left, top, right, bottom) in screenshot pixels of the first element matching `selector`."""
        r = self.js("(e => e && e.getBoundingClientRect().toJSON())(document.querySelector(arguments[0]))",
                    selector)
        assert r is not None, f"no element matches {selector!r}"
        return round(r["left"]), round(r["top"]), round(r["right"]), round(r["bottom"])

    def screenshot(self, path) -> Path:
        """Save the viewport as a PNG of width x height pixels, after the next frames are drawn
        (inside `scripts_off`, where frame callbacks do not run: a frame drawn for the screenshot)."""
        if self._scripts:
            self.js("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
        path = Path(path)
        assert self.driver.save_screenshot(str(path)), f"could not save a screenshot to {path}"
        return path


@contextmanager
def chromium(width: int = 1280, height: int = 900) -> Iterator[Browser]:
    """A headless Debian Chromium with a `width` x `height` viewport; quit on exit."""
    skip_without_chromium()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in (*FLAGS, f"--window-size={width},{height}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"performance": "ALL", "browser": "ALL"})
    service = Service(executable_path=CHROMEDRIVER, log_output=subprocess.DEVNULL)
    driver = webdriver.Chrome(service=service, options=options)
    try:
        driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                               {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        yield Browser(driver, width, height)
    finally:
        driver.quit()

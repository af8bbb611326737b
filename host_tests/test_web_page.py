"""The web page (firmware/web/) in a browser, against the firmware's own web server
(webserver.py) on the simulated printer under `mixstep serve --http`: logging in,
watching a print's temperatures and progress, uploading and printing a file, editing
a mix and seeing the next extrusion follow it, cancelling a print, and the layout on a
phone's screen. The API alone, without a browser: test_webserver.py.

Headless Chromium (Debian's, /usr/bin/chromium) driven by Playwright; skipped where
either is missing, unless MIXSTEP_REQUIRE_ALL=1 (as CI sets), where that fails."""
import os
import re
import shutil
import time
import urllib.error
import urllib.request

import pytest

from mixfw.colours import mix_rgb
from mixstep import paths, serve
from net import free_port, traced_drive_steps

PASSWORD = "mixing-is-fun"
CHROMIUM = "/usr/bin/chromium"
# No network beyond the loopback, nothing downloaded or synced: the printer's page
# has no internet, and neither has CI.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update",
                 "--disable-sync"]
PRINT = paths.ROOT / "testdata" / "short_3tool_m117_prusaslicer.gcode"
SCREENSHOT = paths.ROOT / "docs" / "web_page.png"
# The simulated printer at four times the wall clock: the slicer file's heat-up and
# first layers within a few seconds, with the CPU the simulation takes still modest.
REALTIME = 4
DESKTOP = {"width": 1280, "height": 900}
PHONE = {"width": 390, "height": 844}

# Every toast the page shows, kept for the test: an error the page reports is a
# failure unless the test asked for it.
RECORD_TOASTS = """
window.__toasts = [];
new MutationObserver((changes) => changes.forEach((c) => c.addedNodes.forEach((n) => {
  if (n.dataset && n.dataset.test === 'toast') window.__toasts.push(n.textContent);
}))).observe(document, {childList: true, subtree: true});
"""


def _need(reason):
    if os.environ.get("MIXSTEP_REQUIRE_ALL") == "1":
        pytest.fail(reason + " (MIXSTEP_REQUIRE_ALL=1 asks for every test to run)")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def browser():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _need("playwright is not installed (pip install playwright)")
    if not shutil.which(CHROMIUM):
        _need("%s is not installed (apt-get install chromium)" % CHROMIUM)
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture
def printer(tmp_path):
    """The simulated printer's web page, password set, and its TCP console (for the
    step capture, M7300/M7301): (the page's address, the console's HOST:PORT)."""
    port = free_port()
    tcp = "127.0.0.1:%d" % free_port()
    (tmp_path / "files").mkdir()
    proc = serve.serve_tcp(tcp, realtime=REALTIME, announce=lambda s: None,
                           http="127.0.0.1:%d" % port,
                           settings={"net_password": PASSWORD, "trace_records": 60000},
                           config=tmp_path / "printer.cfg", files=tmp_path / "files")
    url = "http://127.0.0.1:%d/" % port
    try:
        _wait_for_page(url)
        yield url, tcp
    finally:
        serve.stop(proc)


def _wait_for_page(url, timeout_s=30):
    # A whole request each time: a bare connect would hold one of the server's few
    # connection slots until its head timed out.
    deadline = time.time() + timeout_s
    while True:
        try:
            urllib.request.urlopen(url + "api/session", timeout=5).read()
            return
        except (urllib.error.URLError, ConnectionError):
            assert time.time() < deadline, "the web page did not answer at " + url
            time.sleep(0.1)


class Page:
    """A browser tab on the printer's page, and what the test does there."""

    def __init__(self, browser, url, viewport=DESKTOP):
        self.context = browser.new_context(viewport=viewport)
        self.tab = self.context.new_page()
        self.tab.set_default_timeout(20000)
        self.page_errors = []
        self.tab.on("pageerror", lambda e: self.page_errors.append(str(e)))
        self.tab.on("dialog", lambda d: d.accept())  # "Cancel the print?": yes
        self.tab.add_init_script(RECORD_TOASTS)
        self.tab.goto(url)
        self.expected_toasts = []

    def text(self, selector):
        return self.tab.inner_text(selector)

    def wait(self, js, arg=None, timeout_s=20):
        """Until the JavaScript function js(arg) is true in the page."""
        self.tab.wait_for_function(js, arg=arg, timeout=timeout_s * 1000)

    def wait_text(self, selector, pattern, timeout_s=20):
        """Until the element's text matches the regular expression; the match."""
        self.wait("([s, p]) => { const e = document.querySelector(s);"
                  " return e && new RegExp(p).test(e.textContent); }",
                  [selector, pattern], timeout_s)
        return re.search(pattern, self.tab.text_content(selector))

    def log_in(self, password=PASSWORD):
        """Log in through the form; after a wrong password the printer answers 429
        for a moment (the page says "try again in N s"), so try until it lets in."""
        deadline = time.time() + 60
        while True:
            self.tab.fill("#password", password)
            self.tab.click("#login-btn")
            self.wait("() => !document.getElementById('app').hidden"
                      " || document.getElementById('login-error').textContent")
            if self.tab.is_visible("#app"):
                return
            assert "try again" in self.text("#login-error"), self.text("#login-error")
            assert time.time() < deadline
            time.sleep(0.5)

    def status(self):
        """The printer's /api/status, through the page's session."""
        return self.tab.evaluate("fetch('/api/status').then((r) => r.json())")

    def send(self, line):
        """A line through the console's input box."""
        self.tab.fill("#console-input", line)
        self.tab.press("#console-input", "Enter")

    def console_lines(self):
        return self.tab.text_content("#console-log").split("\n")

    def ask(self, line, answer, timeout_s=30):
        """Send a line in the console; the first new line matching answer (a regular
        expression) that the printer writes back."""
        before = len([l for l in self.console_lines() if re.search(answer, l)])
        self.send(line)
        self.wait("([p, n]) => document.getElementById('console-log').textContent"
                  ".split('\\n').filter((l) => new RegExp(p).test(l)).length > n",
                  [answer, before], timeout_s)
        return [l for l in self.console_lines() if re.search(answer, l)][before]

    def toasts(self):
        return self.tab.evaluate("window.__toasts")

    def close(self):
        """End the tab; what went wrong in it, that the test didn't expect, fails."""
        toasts = self.toasts()
        self.context.close()
        assert not self.page_errors, self.page_errors
        unexpected = [t for t in toasts if not any(re.search(p, t) for p in self.expected_toasts)
                      and not t.startswith("Uploaded ")]
        assert not unexpected, unexpected


@pytest.fixture
def open_page(browser, printer):
    """open_page(viewport=DESKTOP): a tab on the printer's page; closed after the test,
    which fails on a script error or a toast it didn't expect."""
    pages = []

    def make(viewport=DESKTOP):
        pages.append(Page(browser, printer[0], viewport))
        return pages[-1]

    yield make
    for p in pages:
        p.close()


def _rgb_css(hex_rgb):
    r, g, b = (int(hex_rgb[i:i + 2], 16) for i in (1, 3, 5))
    return "rgb(%d, %d, %d)" % (r, g, b)


def _background(page, selector):
    return page.tab.eval_on_selector(selector, "(e) => getComputedStyle(e).backgroundColor")


def _mix_rgb(weights, drive_rgb):
    """The colour a mix prints, as the firmware works it out, from "#rrggbb" colours."""
    return "#%06x" % mix_rgb(weights, [int(c[1:], 16) for c in drive_rgb])


def _upload(page, path):
    page.tab.set_input_files("#upload-file", str(path))
    page.tab.click("#upload")
    page.tab.wait_for_selector('#files tr[data-file="%s"]' % path.name)


def _ratio(mix):
    total = sum(mix)
    return [round(w / total, 6) for w in mix]


def test_log_in_and_see_the_status(open_page):
    page = open_page()
    page.tab.wait_for_selector("#login", state="visible")
    assert page.tab.is_hidden("#app")
    page.tab.fill("#password", "not-the-password")
    page.tab.click("#login-btn")
    assert page.wait_text("#login-error", "wrong password")
    assert page.tab.is_hidden("#app")

    page.log_in()
    page.wait_text("#state", "^idle$")
    s = page.status()
    assert page.wait_text("#pos", r"X 0\.00 +Y 0\.00 +Z 0\.00")
    assert page.wait_text("#heaters", r"hotend \d+\.\d / 0 °C")
    assert page.text("#tool") == "T%d" % s["tool"]
    assert _background(page, "#tool-swatch") == _rgb_css(s["tools"][s["tool"]]["rgb"])
    assert page.text("#queue") == "0 moves"
    assert page.text("#job") == "no file"
    # The console hears the printer: an M114 sent from the page is answered there.
    assert re.match(r"X:0\.00 Y:0\.00 Z:0\.00", page.ask("M114", r"^X:"))


@pytest.mark.slow
def test_watch_a_print_then_cancel_it(open_page):
    page = open_page()
    page.log_in()
    _upload(page, PRINT)
    row = '#files tr[data-file="%s"]' % PRINT.name
    assert "40.5 kB" in page.text(row)
    page.tab.click(row + " [data-test=file-print]")
    page.wait_text("#state", "^printing$")

    # The slicer's M109 S200: the hot end's reading climbs on the graph.
    page.wait("() => parseFloat(/hotend ([\\d.]+) \\/ 200/.exec("
              "document.getElementById('heaters').textContent)?.[1]) >= 100", timeout_s=60)
    # Past the heat-up, moving: progress through the file and the layer's message.
    page.wait_text("#message", r"^Layer \d", timeout_s=60)
    page.wait("() => parseInt(document.getElementById('progress-text').textContent) >= 10",
              timeout_s=60)
    assert int(page.tab.get_attribute("#graph", "data-points")) >= 10
    # The hot end's trace is drawn: pixels of its colour on the canvas.
    hot_pixels = page.tab.evaluate("""() => {
        const c = document.getElementById('graph');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 0; i < d.length; i += 4)
          if (d[i] > 180 && d[i + 1] < 130 && d[i + 2] < 100 && d[i + 3] > 128) n++;
        return n; }""")
    assert hot_pixels > 50, hot_pixels
    assert page.tab.is_disabled("[data-jog='X+']")  # no jogging under a print
    assert page.tab.is_enabled("#pause") and page.tab.is_enabled("#cancel")
    # docs/web_page.png: made where missing, remade with MIXSTEP_DOCS_SCREENSHOT=1 (a
    # screenshot's bytes differ every run, and the tree should stay clean).
    if os.environ.get("MIXSTEP_DOCS_SCREENSHOT") == "1" or not SCREENSHOT.exists():
        page.tab.screenshot(path=str(SCREENSHOT))

    # The flash is the print's while it runs: an upload is refused, and the page says so.
    page.expected_toasts.append(r"^Upload short_3tool_m117_prusaslicer\.gcode: .*prints")
    page.tab.set_input_files("#upload-file", str(PRINT))
    page.tab.click("#upload")
    page.wait("() => window.__toasts.some((t) => /prints/.test(t))")

    page.tab.click("#cancel")  # M524, after the page's "Cancel the print?"
    page.wait_text("#state", "^idle$")
    assert page.text("#job") == "no file"
    page.wait_text("#queue", "^0 moves$")
    log = page.console_lines()
    assert "> M524" in log and "ok" in log[log.index("> M524"):], log[-10:]
    assert page.status()["job"]["state"] == "idle"


@pytest.mark.slow
def test_upload_a_file_print_it_and_delete_it(open_page, tmp_path):
    page = open_page()
    page.log_in()
    job = tmp_path / "square.gcode"
    job.write_text("G28\nG1 X20 Y10 F6000\nG1 X30\nG1 Z2 F600\nM117 square done\n")
    _upload(page, job)
    row = '#files tr[data-file="square.gcode"]'
    page.tab.click(row + " [data-test=file-print]")
    page.wait_text("#message", "^square done$")
    page.wait_text("#pos", r"X 30\.00 +Y 10\.00 +Z 2\.00")
    page.wait_text("#state", "^(idle|done)$")
    page.tab.click(row + " [data-test=file-delete]")
    page.tab.wait_for_selector(row, state="detached")
    assert "square.gcode" not in [f["name"] for f in page.tab.evaluate(
        "fetch('/api/files').then((r) => r.json())")["files"]]


@pytest.mark.slow
def test_a_mix_edited_on_the_page_is_what_the_next_extrusion_feeds(open_page, printer,
                                                                   tmp_path, monkeypatch):
    """The mix saved in the editor is what the next extrusion feeds: M167's counts,
    and each drive's steps in the capture pulled from the printer (`mixstep trace
    pull`), which trace check holds to the lines the page sent."""
    page = open_page()
    page.log_in()
    page.ask("M7300 S1", "^ok")  # the step capture on: what follows is checked
    page.wait("() => document.querySelectorAll('#mix-sliders input[type=range]').length > 1")
    s = page.status()
    drives = s["drives"]
    weights = [25, 75] + [0] * (drives - 2)
    page.tab.select_option("#mix-tool", "0")
    for i, w in enumerate(weights):
        page.tab.fill("#mix-w%d" % i, str(w))
    # The preview is the server's rule, worked out in the page before anything is sent.
    expected = _mix_rgb(weights, s["drive_rgb"])
    assert page.text("#mix-preview-rgb") == expected
    assert _background(page, "#mix-preview") == _rgb_css(expected)
    page.tab.click("#mix-save")  # M567 P0 E25:75:0..., M500
    page.wait("() => document.getElementById('mix-now').style.background"
              " === document.getElementById('mix-preview').style.background")
    s = page.status()
    assert _ratio(s["tools"][0]["mix"]) == _ratio(weights)
    assert s["tools"][0]["rgb"] == expected
    assert [int(page.tab.input_value("#mix-w%d" % i)) for i in range(drives)] == weights

    # The next extrusion with T0 feeds 25 % from e0 and 75 % from e1.
    page.ask("M302 P1", "^ok")  # cold extrusion: the hot end needn't heat for this
    before = _fed(page.ask("M167", "^echo:filament used mm"))
    for line in ("T0", "G92 E0", "G1 E40 F600", "M400"):
        page.ask(line, "^ok")
    after = _fed(page.ask("M167", "^echo:filament used mm"))
    fed = [a - b for a, b in zip(after, before)]
    assert fed == pytest.approx([10.0, 30.0] + [0.0] * (drives - 2), abs=0.02), fed
    # The capture: each line the page sent since M7300 (its console echoes them).
    log = page.console_lines()
    sent = [l[2:] for l in log[log.index("> M7300 S1") + 1:] if l.startswith("> ")]
    assert "M567 P0 E25:75:%s" % ":".join(["0"] * (drives - 2)) in sent, sent
    spm = 415  # the simulated board's filament steps per mm
    assert traced_drive_steps(tmp_path, printer[1], sent, PASSWORD, monkeypatch) == (
        10 * spm, 30 * spm)

    # A drive's filament colour: the tool's colour follows, on the server and the page.
    page.tab.fill("#drive-rgb1", "#000000")  # M926 Idrive_colour_rgb_1 V0, M930
    page.wait("() => fetch('/api/status').then((r) => r.json())"
              ".then((s) => s.drive_rgb[1] === '#000000')")
    s = page.status()
    expected = _mix_rgb(weights, s["drive_rgb"])
    assert s["tools"][0]["rgb"] == expected
    page.wait("(c) => getComputedStyle(document.getElementById('mix-now')).backgroundColor"
              " === c", _rgb_css(expected))
    assert page.text("#mix-preview-rgb") == expected

    # A gradient along Z from T0 to T1, then off.
    page.tab.fill("#grad-z0", "0")
    page.tab.fill("#grad-z1", "5")
    page.tab.select_option("#grad-a", "0")
    page.tab.select_option("#grad-b", "1")
    page.tab.click("#grad-on")  # M166 A0 Z5 I0 J1 S1
    assert re.match(r"echo:gradient along Z on: 0:[\d.:]+, 5:[\d.:]+$",
                    page.ask("M166", "^echo:.*gradient"))
    page.tab.click("#grad-off")  # M166 S0
    # The answer with "off" itself: the "on" answer above can reach the log late.
    assert page.ask("M166", "^echo:gradient along Z off")


def _fed(line):
    """M167's answer, "echo:filament used mm e0:1.000 e1:...": mm per drive."""
    return [float(v) for v in re.findall(r"e\d+:(-?[\d.]+)", line)]


@pytest.mark.slow
def test_a_phone_sized_screen_shows_one_column(open_page):
    page = open_page(PHONE)
    page.log_in()
    page.wait_text("#state", "^idle$")
    page.wait("() => document.getElementById('graph').dataset.points > 1")
    width = page.tab.evaluate("() => [document.documentElement.scrollWidth,"
                              " document.documentElement.clientWidth]")
    assert width[0] <= width[1], width  # nothing to scroll sideways
    boxes = page.tab.evaluate("() => [...document.querySelectorAll('main > .card')]"
                              ".map((c) => { const r = c.getBoundingClientRect();"
                              " return [r.left, r.right, r.top]; })")
    assert len(boxes) >= 6
    assert len({round(left) for left, _, _ in boxes}) == 1, boxes  # one column
    assert all(right <= PHONE["width"] for _, right, _ in boxes), boxes
    assert [top for _, _, top in boxes] == sorted(top for _, _, top in boxes)

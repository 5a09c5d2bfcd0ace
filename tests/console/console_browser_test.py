#!/usr/bin/python3
"""Browser test of recogd's web console: loads every page in headless Chromium against a running
recogd and checks what a person would see.

Usage:
  console_browser_test.py --url http://127.0.0.1:PORT --map corridor --min-loops 1 --model NAME
      --photo PATH --camera fx,fy,cx,cy --expect-object NAME --screenshots DIR [--token T]
      [--place-photo PATH] [--expect-chart NAME]

Checks, one line each ("ok: ..." / "FAIL: ..."):
  - #/maps: the row of --map, with frames > 0;
  - #/maps/<map>: at least --min-loops loops whose canvas is drawn and that have >= 12 inliers;
  - #/models: the row of --model; #/models/<model>: more than 100 points drawn (WebGL);
  - #/try: a file that is not an image gives an error that says so, and the page keeps working;
    --photo with --camera finds --expect-object;
  - #/try with --place-photo: the photo is placed in --map (div#try-place has a data-match) and
    drawn beside the matched frame;
  - #/live: at least one sample, and the four charts;
  - #/charts with --expect-chart: the chart of that name is drawn, with at least one series;
  - no SEVERE message in the browser's console, except 404s of thumbnails (frames whose map kept
    no image).
Screenshots: maps.png, map.png, models.png, model.png, try.png, live.png in --screenshots, and
try-place.png, charts.png with the options that check them.
Exit status: 0 all passed, 1 a check failed, 77 (skip) without Chromium, chromedriver or Selenium.

Uses Debian's chromium, chromium-driver and python3-selenium (4.8). Headless Chromium has no GPU
here: WebGL runs on SwiftShader (--enable-unsafe-swiftshader --use-angle=swiftshader).
"""
import argparse
import os
import re
import shutil
import sys
import tempfile
import time

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
WAIT_S = 30
ERROR_GRACE_S = 3  # an error shown this long without the content: give up waiting
_GAVE_UP = object()
CHROMIUM_FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--window-size=1400,1000",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--enable-unsafe-swiftshader",  # software WebGL for the model page's three.js view
    "--use-angle=swiftshader",
    "--hide-scrollbars",
    "--lang=en-US",
]


def skip(message):
    print(f"skip: {message}")
    sys.exit(77)


try:
    from selenium import webdriver
    from selenium.common.exceptions import TimeoutException, WebDriverException
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select, WebDriverWait
except ImportError:
    skip("python3-selenium is not installed (apt-get install python3-selenium)")

# Number of opaque pixels and of distinct colours (sampled) of a canvas: a drawn canvas has many.
CANVAS_STATS_JS = """
const c = arguments[0];
if (!c || !c.width || !c.height) return [0, 0];
let data;
try { data = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; }
catch (e) { return [-1, 0]; }
let opaque = 0;
const colours = new Set();
for (let i = 0; i < data.length; i += 4) {
  if (data[i + 3] > 0) opaque++;
  if ((i / 4) % 97 === 0) colours.add((data[i] >> 3) + ',' + (data[i + 1] >> 3) + ',' + (data[i + 2] >> 3) + ',' + (data[i + 3] >> 6));
}
return [opaque / (c.width * c.height), colours.size];
"""


class Checks:
    def __init__(self):
        self.failures = 0
        self.passed = 0

    def ok(self, what):
        self.passed += 1
        print(f"ok: {what}", flush=True)

    def fail(self, what):
        self.failures += 1
        print(f"FAIL: {what}", flush=True)

    def check(self, condition, what, detail=""):
        if condition:
            self.ok(what)
        else:
            self.fail(f"{what}{': ' + detail if detail else ''}")
        return condition


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--url", required=True, help="the console, e.g. http://127.0.0.1:8080")
    p.add_argument("--map", required=True)
    p.add_argument("--min-loops", type=int, default=1)
    p.add_argument("--model", required=True)
    p.add_argument("--photo", required=True)
    p.add_argument("--camera", required=True, help="fx,fy,cx,cy of --photo")
    p.add_argument("--expect-object", required=True)
    p.add_argument("--screenshots", required=True)
    p.add_argument("--token", default="")
    p.add_argument("--place-photo", default="", help="a photo of a place in --map, to find in #/try")
    p.add_argument("--expect-chart", default="", help="a chart that #/charts must draw (its name)")
    a = p.parse_args()
    a.url = a.url.rstrip("/")
    try:
        a.camera = [float(v) for v in a.camera.split(",")]
        assert len(a.camera) == 4
    except (ValueError, AssertionError):
        p.error("--camera takes four numbers: fx,fy,cx,cy")
    if not os.path.isfile(a.photo):
        p.error(f"--photo {a.photo}: no such file")
    a.photo = os.path.abspath(a.photo)
    if a.place_photo:
        if not os.path.isfile(a.place_photo):
            p.error(f"--place-photo {a.place_photo}: no such file")
        a.place_photo = os.path.abspath(a.place_photo)
    return a


def start_browser():
    for path in (CHROMIUM, CHROMEDRIVER):
        if not os.access(path, os.X_OK):
            skip(f"{path} is missing (apt-get install chromium chromium-driver)")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(WAIT_S)
    return driver


def css(driver, selector):
    return driver.find_elements(By.CSS_SELECTOR, selector)


def error_texts(driver):
    return [e.text for e in css(driver, "p.error") if e.text.strip()]


def wait_for(driver, condition, what, checks, stop_on_error=True):
    """Waits up to WAIT_S for condition(driver) to be truthy; returns its value, or None after
    failing the check with the page's visible errors. With stop_on_error, gives up early when the
    page has shown an error (p.error) for ERROR_GRACE_S without the condition coming true."""
    first_error = []

    def poll(d):
        value = condition(d)
        if value:
            return value
        if stop_on_error and error_texts(d):
            if not first_error:
                first_error.append(time.monotonic())
            elif time.monotonic() - first_error[0] > ERROR_GRACE_S:
                return _GAVE_UP
        return None

    try:
        value = WebDriverWait(driver, WAIT_S, poll_frequency=0.25).until(poll)
    except TimeoutException:
        value = _GAVE_UP
    if value is _GAVE_UP:
        errors = error_texts(driver)
        checks.fail(f"{what} (" + (f"the page says: {' | '.join(errors)}" if errors else f"nothing after {WAIT_S} s") + ")")
        return None
    return value


def wait_css(driver, selector, what, checks):
    return wait_for(driver, lambda d: (css(d, selector) or [None])[0], what, checks)


def number(text):
    digits = re.sub(r"[^0-9.\-]", "", text or "")
    try:
        return float(digits)
    except ValueError:
        return None


def open_page(driver, url, route):
    driver.get(f"{url}/#/{route}")


def screenshot(driver, directory, name, checks):
    path = os.path.join(directory, name)
    try:
        time.sleep(0.3)  # let the last frame paint
        driver.save_screenshot(path)
    except WebDriverException as e:
        checks.fail(f"screenshot {name}: {e.msg}")


class ConsoleLog:
    """The browser's console messages, read after each step (reading empties Chromium's buffer)."""

    def __init__(self, driver):
        self.driver = driver
        self.severe = []  # (step, message)

    def collect(self, step, allowed=()):
        try:
            entries = self.driver.get_log("browser")
        except WebDriverException:
            return
        for entry in entries:
            if entry.get("level") != "SEVERE":
                continue
            message = entry.get("message", "")
            # a frame whose map kept no image: the page draws a grey box instead
            if "/thumbnail" in message and "404" in message:
                continue
            if any(re.search(pattern, message) for pattern in allowed):
                continue
            self.severe.append((step, message))


def check_maps(driver, a, checks):
    open_page(driver, a.url, "maps")
    row = wait_css(driver, f'table#maps-table tr[data-map="{a.map}"]', f"maps: a row for map {a.map}", checks)
    if row is None:
        return
    cells = row.find_elements(By.TAG_NAME, "td")
    frames = number(cells[1].text) if len(cells) > 1 else None
    checks.check(frames is not None and frames > 0, f"maps: map {a.map} has frames ({cells[1].text if len(cells) > 1 else '?'})",
                 "expected more than 0")
    links = row.find_elements(By.CSS_SELECTOR, f'a[href="#/maps/{a.map}"]')
    checks.check(bool(links), f"maps: the name links to #/maps/{a.map}")


def check_map(driver, a, checks):
    open_page(driver, a.url, f"maps/{a.map}")
    title = wait_css(driver, "h2#map-title", "map: the title", checks)
    if title is not None:
        checks.check(title.text.strip() == a.map, f"map: the title is {a.map!r}", f"got {title.text!r}")
    settings = wait_css(driver, "dl#map-settings dt", "map: the settings list", checks)
    if settings is not None:
        checks.ok(f"map: {len(css(driver, 'dl#map-settings dt'))} settings shown")

    if a.min_loops <= 0:
        found = wait_for(driver, lambda d: css(d, "#no-loops") or css(d, "div.loop"), "map: the loops or #no-loops", checks)
        if found:
            checks.ok("map: the loops section is shown")
        return

    def good_loops(d):
        if css(d, "#no-loops"):
            return "none"
        good = []
        for loop in css(d, "div#loops div.loop"):
            inliers = number(loop.get_attribute("data-inliers"))
            canvases = loop.find_elements(By.CSS_SELECTOR, "canvas.loop-canvas")
            if not canvases or inliers is None or inliers < 12:
                continue
            opaque, colours = d.execute_script(CANVAS_STATS_JS, canvases[0])
            if opaque > 0.5 and colours > 8:
                good.append(loop)
        return good if len(good) >= a.min_loops else None

    good = wait_for(driver, good_loops, f"map: at least {a.min_loops} drawn loop(s) with >= 12 inliers", checks)
    if good == "none":
        checks.fail(f"map: at least {a.min_loops} loop(s): the page says the map has none ({css(driver, '#no-loops')[0].text!r})")
    elif good:
        first = good[0]
        checks.ok(f"map: {len(good)} drawn loop(s) with >= 12 inliers (first: frame {first.get_attribute('data-frame')} "
                  f"<-> frame {first.get_attribute('data-match')}, {first.get_attribute('data-inliers')} inliers)")


def check_models(driver, a, checks):
    open_page(driver, a.url, "models")
    row = wait_css(driver, f'table#models-table tr[data-model="{a.model}"]', f"models: a row for model {a.model}", checks)
    if row is not None:
        checks.check(bool(row.find_elements(By.CSS_SELECTOR, f'a[href="#/models/{a.model}"]')),
                     f"models: the name links to #/models/{a.model}")


def check_model(driver, a, checks):
    open_page(driver, a.url, f"models/{a.model}")
    title = wait_css(driver, "h2#model-title", "model: the title", checks)
    if title is not None:
        checks.check(title.text.strip() == a.model, f"model: the title is {a.model!r}", f"got {title.text!r}")
    wait_css(driver, "dl#model-info dt", "model: the description", checks)

    def drawn(d):
        view = (css(d, "div#points-view[data-points]") or [None])[0]
        return view.get_attribute("data-points") if view is not None else None

    points = wait_for(driver, drawn, "model: the 3D points are drawn (data-points)", checks)
    if points is not None:
        n = number(points)
        checks.check(n is not None and n > 100, f"model: {points} points drawn", "expected more than 100")
        checks.check(bool(css(driver, "div#points-view canvas")), "model: the three.js canvas is there")
    if wait_css(driver, "div#views", "model: the training views section", checks) is not None:
        checks.ok(f"model: {len(css(driver, 'div#views figure.view'))} training view(s) shown")


def upload_and_run(driver, path, target, camera):
    file_input = css(driver, "input#try-file")[0]
    file_input.send_keys(path)
    Select(css(driver, "select#try-target")[0]).select_by_value(target)
    for name, value in zip(("fx", "fy", "cx", "cy"), camera or ["", "", "", ""]):
        field = css(driver, f"input#try-{name}")[0]
        field.clear()
        if value != "":
            field.send_keys(repr(float(value)))
    css(driver, "button#try-run")[0].click()


def try_finished(d):
    """The Try page's status once the answer came (the click set "recognising…" before returning)."""
    status = (css(d, "p#try-status") or [None])[0]
    return status if status is not None and "recognising" not in status.text else None


def check_canvas(driver, canvas, what, checks):
    opaque, colours = driver.execute_script(CANVAS_STATS_JS, canvas)
    checks.check(opaque > 0.5 and colours > 8, what, f"opaque {opaque}, colours {colours}")


def check_try(driver, a, checks, log, tmp):
    open_page(driver, a.url, "try")
    if wait_css(driver, "button#try-run", "try: the form", checks) is None:
        return
    log.collect("try (before the bad file)")

    # Not an image: an error that says so, and the page keeps working.
    bad = os.path.join(tmp, "notes.txt")
    with open(bad, "w") as f:
        f.write("this is not an image\n")
    upload_and_run(driver, bad, "objects", None)

    def error_shown(d):
        status = (css(d, "p#try-status") or [None])[0]
        if status is not None and "error" in (status.get_attribute("class") or ""):
            return status.text
        errors = error_texts(d)
        return errors[0] if errors else None

    message = wait_for(driver, error_shown, "try: a file that is not an image gives an error", checks, stop_on_error=False)
    if message:
        checks.check(re.search(r"image|jpe?g|png", message, re.I) is not None,
                     f"try: the error says what is wrong ({message!r})", "expected it to mention the image")
    checks.check(bool(css(driver, "button#try-run")) and bool(css(driver, "nav a")) and not css(driver, "li.detected-object"),
                 "try: the page still works after the bad file")
    # a 400 answer to the bad file is expected, if the front end sent it at all
    log.collect("try (the bad file)", allowed=(r"/api/rpc/.* 400", r"status of 400"))

    upload_and_run(driver, a.photo, "objects", a.camera)
    status = wait_for(driver, try_finished, f"try: an answer for {os.path.basename(a.photo)}", checks, stop_on_error=False)
    if status is None:
        return
    found = css(driver, f'ul#try-results li.detected-object[data-name="{a.expect_object}"]')
    if found:
        checks.ok(f"try: {a.expect_object} recognised ({found[0].text}; {status.text})")
    elif "error" in (status.get_attribute("class") or ""):
        checks.fail(f"try: recognition failed: {status.text!r}")
    else:
        results = css(driver, "ul#try-results")
        checks.fail(f"try: {a.expect_object} not recognised; the page lists: {results[0].text if results else 'nothing'!r}")
    canvas = css(driver, "canvas#try-canvas")
    if checks.check(bool(canvas), "try: the photo is drawn (canvas#try-canvas)"):
        check_canvas(driver, canvas[0], "try: the result canvas is not blank", checks)


def check_try_place(driver, a, checks):
    open_page(driver, a.url, "try")
    target = f"map:{a.map}"
    if wait_css(driver, f'select#try-target option[value="{target}"]', f"try place: {a.map} is a target", checks) is None:
        return
    upload_and_run(driver, a.place_photo, target, None)
    photo = os.path.basename(a.place_photo)
    status = wait_for(driver, try_finished, f"try place: an answer for {photo}", checks, stop_on_error=False)
    if status is None:
        return
    place = css(driver, "div#try-place")
    if not place:
        checks.fail(f"try place: no div#try-place (the page says {status.text!r})")
        return
    match = place[0].get_attribute("data-match") or ""
    if match:
        checks.ok(f"try place: {photo} recognised in {a.map} ({place[0].text}; {status.text})")
    else:
        checks.fail(f"try place: {photo} not recognised in {a.map}: {place[0].text!r} "
                    f"(status {place[0].get_attribute('data-status')})")
    canvas = css(driver, "canvas#try-canvas")
    if checks.check(bool(canvas), "try place: the photo is drawn (canvas#try-canvas)"):
        check_canvas(driver, canvas[0], "try place: the canvas is not blank", checks)


def check_live(driver, a, checks):
    open_page(driver, a.url, "live")

    def samples(d):
        status = (css(d, "p#live-status[data-samples]") or [None])[0]
        if status is None:
            return None
        n = number(status.get_attribute("data-samples"))
        return status if n is not None and n >= 1 else None

    status = wait_for(driver, samples, "live: at least one sample (data-samples >= 1)", checks)
    if status is not None:
        checks.ok(f"live: {status.text}")
    for chart in ("chart-throughput", "chart-latency", "chart-queue", "chart-errors"):
        checks.check(bool(css(driver, f"canvas#{chart}")), f"live: canvas#{chart}")


def chart_drawn(driver, canvas):
    """(drawn, opaque fraction, colours) of a chart's canvas. Its background stays transparent
    (Chart.js draws only the axes, text, lines and points): drawn means enough opaque pixels and
    several colours."""
    opaque, colours = driver.execute_script(CANVAS_STATS_JS, canvas)
    size = driver.execute_script("return arguments[0].width * arguments[0].height;", canvas)
    return opaque * size >= 2000 and colours >= 3, opaque, colours


def check_charts(driver, a, checks):
    open_page(driver, a.url, "charts")
    selector = f'section.chart[data-name="{a.expect_chart}"]'

    def drawn(d):
        if css(d, "#charts-none"):
            return "none"
        if css(d, "section.chart") and not css(d, selector):  # the page places every chart at once
            return "absent"
        section = (css(d, selector + "[data-series]") or [None])[0]
        canvas = section.find_elements(By.CSS_SELECTOR, "canvas.chart-canvas") if section is not None else []
        return section if canvas and chart_drawn(d, canvas[0])[0] else None

    section = wait_for(driver, drawn, f"charts: the chart {a.expect_chart} is drawn", checks)
    if section == "none":
        checks.fail(f"charts: the chart {a.expect_chart}: the page says {css(driver, '#charts-none')[0].text!r}")
        return
    if section == "absent":
        names = [e.get_attribute("data-name") for e in css(driver, "section.chart")]
        checks.fail(f"charts: no chart named {a.expect_chart}; the page shows {', '.join(names)}")
        return
    if section is None:
        return
    _, opaque, colours = chart_drawn(driver, section.find_element(By.CSS_SELECTOR, "canvas.chart-canvas"))
    checks.ok(f"charts: {a.expect_chart} drawn ({opaque:.1%} of the canvas, {colours} colours)")
    series = number(section.get_attribute("data-series"))
    title = section.find_elements(By.TAG_NAME, "h3")
    checks.check(series is not None and series >= 1,
                 f"charts: {a.expect_chart} has {section.get_attribute('data-series')} series "
                 f"({title[0].text if title else 'no title'!r})", "expected at least 1")


def set_token(driver, a, checks, log):
    open_page(driver, a.url, "maps")
    field = wait_css(driver, "input#token", "token: the header's token field", checks)
    if field is None:
        return
    field.clear()
    field.send_keys(a.token)
    css(driver, "button#token-save")[0].click()
    stored = driver.execute_script("return localStorage.getItem('recog.token');")
    checks.check(stored == a.token, "token: saved in localStorage")
    # the first load ran without the token: its 401s are expected
    wait_css(driver, "table#maps-table", "token: the maps load with the token", checks)
    log.collect("token", allowed=(r"status of 401",))


def main():
    a = parse_args()
    os.makedirs(a.screenshots, exist_ok=True)
    checks = Checks()
    try:
        driver = start_browser()
    except WebDriverException as e:
        print(f"FAIL: cannot start headless Chromium: {e.msg}")
        return 1
    log = ConsoleLog(driver)
    tmp = tempfile.mkdtemp(prefix="console-test-")
    try:
        if a.token:
            set_token(driver, a, checks, log)
        steps = [
            ("maps", lambda: check_maps(driver, a, checks), "maps.png"),
            ("map", lambda: check_map(driver, a, checks), "map.png"),
            ("models", lambda: check_models(driver, a, checks), "models.png"),
            ("model", lambda: check_model(driver, a, checks), "model.png"),
            ("try", lambda: check_try(driver, a, checks, log, tmp), "try.png"),
            ("live", lambda: check_live(driver, a, checks), "live.png"),
        ]
        if a.place_photo:
            steps.insert(5, ("try place", lambda: check_try_place(driver, a, checks), "try-place.png"))
        if a.expect_chart:
            steps.append(("charts", lambda: check_charts(driver, a, checks), "charts.png"))
        for name, step, png in steps:
            try:
                step()
            except WebDriverException as e:
                checks.fail(f"{name}: the browser failed: {e.msg}")
            screenshot(driver, a.screenshots, png, checks)
            log.collect(name)
        if log.severe:
            counts = {}
            for entry in log.severe:
                counts[entry] = counts.get(entry, 0) + 1
            for (step, message), n in counts.items():
                checks.fail(f"console: SEVERE message on the {step} page: {message}" + (f" ({n} times)" if n > 1 else ""))
        else:
            checks.ok("console: no SEVERE JavaScript message")
    finally:
        try:
            driver.quit()
        except WebDriverException:
            pass
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"{checks.passed} passed, {checks.failures} failed")
    return 1 if checks.failures else 0


if __name__ == "__main__":
    sys.exit(main())

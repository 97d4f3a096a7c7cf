"""The report's comparison viewer in a real browser: Selenium driving Debian's chromium through its chromedriver,
headless, on a report of the smoke suite (suites/smoke.toml, its cases that need no Mitsuba render: the reference
against the closed forms, a planted fault among them). It filters the summary, opens a case's viewer, flips it,
moves the exposure slider, reads the probe at a known pixel against the case's EXRs, goes through every mode, and
fails on any JavaScript error the browser logged. Skipped, with the reason, where no browser can be started.

``HARNESS_VIEWER_SCREENSHOTS=DIR`` keeps a screenshot of each mode in DIR.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import os
import shutil
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from conftest import ROOT

from harness.files.imageio import read_exr, tonemap_srgb8
from harness.report import write_suite_report
from harness.running.cases import load_suite
from harness.running.schedule import run_suite
from harness.scene import load_scene

pytestmark = pytest.mark.slow  # renders and starts a browser

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--window-size=1400,1400")
CASE = "furnace/mutant-double-emission"


@pytest.fixture(scope="module")
def smoke_report(tmp_path_factory) -> Path:
    """The smoke suite's cases judged against a closed form by the reference (no Mitsuba render), and the report."""
    suite = load_suite(ROOT / "suites" / "smoke.toml")
    cases = tuple(c for c in suite.cases if c.renderer == "reference" and c.against.kind == "ground-truth"
                  and load_scene(c.scene).closed_form)
    assert CASE in [c.name for c in cases] and len(cases) >= 3
    out = tmp_path_factory.mktemp("smoke") / "out"
    run_suite(dataclasses.replace(suite, cases=cases), out)
    write_suite_report(out / "results.json", out)
    return out


def _no_browser(reason: str):
    """Skip, or fail where the run was told a browser is there (``HARNESS_REQUIRE_BROWSER=1``: ``.ci/run`` sets it
    once chromium and chromedriver are installed, so that CI cannot pass with the browser tests silently skipped)."""
    if os.environ.get("HARNESS_REQUIRE_BROWSER") == "1":
        pytest.fail(f"HARNESS_REQUIRE_BROWSER=1, but {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    try:
        from selenium import webdriver
        from selenium.common.exceptions import WebDriverException
    except ImportError:
        _no_browser("selenium is not installed (pip install -e '.[test]')")

    if not (shutil.which(CHROMIUM) and shutil.which(CHROMEDRIVER)):
        _no_browser(f"no browser: {CHROMIUM} and {CHROMEDRIVER} are needed (apt-get install chromium chromium-driver)")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        driver = webdriver.Chrome(service=webdriver.ChromeService(CHROMEDRIVER), options=options)
    except WebDriverException as err:
        _no_browser(f"chromium could not be started: {str(err.msg or err).splitlines()[0]}")
    driver.set_script_timeout(20)
    yield driver
    driver.quit()


def _errors(driver) -> list[dict]:
    return [entry for entry in driver.get_log("browser") if entry["level"] in ("SEVERE", "ERROR")]


def _canvas(driver, root) -> np.ndarray:
    """The viewer canvas's pixels (RGB bytes), through a PNG (lossless; far quicker than its pixels as a list)."""
    uri = driver.execute_script("return arguments[0].querySelector('[data-canvas]').toDataURL('image/png');", root)
    return iio.imread(base64.b64decode(uri.split(",", 1)[1]), extension=".png")[..., :3]


def _values(root, key: str) -> list[float]:
    from selenium.webdriver.common.by import By

    text = root.find_element(By.CSS_SELECTOR, f'[data-probe="{key}"]').get_attribute("data-values")
    return [float(v) for v in text.split()]


def _shoot(driver, root, name: str) -> None:
    folder = os.environ.get("HARNESS_VIEWER_SCREENSHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        root.screenshot(str(Path(folder) / f"{name}.png"))


def test_the_viewer_in_a_real_browser(smoke_report, browser):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import WebDriverWait

    driver = browser
    results = json.loads((smoke_report / "results.json").read_text())
    driver.get((smoke_report / "index.html").as_uri())

    # the Failures filter: the rows of the cases that failed, no other
    driver.find_element(By.CSS_SELECTOR, '[data-filter="failures"]').click()
    shown = [row.find_element(By.TAG_NAME, "a").text for row in driver.find_elements(By.CSS_SELECTOR, "tr[data-status]")
             if row.is_displayed()]
    failed = [r["name"] for r in results["cases"] if r["status"] == "fail"]
    assert shown == failed and CASE in failed and len(shown) < len(results["cases"])
    driver.find_element(By.CSS_SELECTOR, '[data-filter="all"]').click()

    # open the planted fault's viewer: its data comes from report/<case>/viewer.js through a <script src> tag
    index = [r["name"] for r in results["cases"]].index(CASE)
    section = driver.find_element(By.ID, f"case-{index}")
    button = section.find_element(By.CSS_SELECTOR, "[data-open-viewer]")
    driver.execute_script("arguments[0].scrollIntoView()", button)
    button.click()
    root = section.find_element(By.CSS_SELECTOR, "[data-viewer]")
    WebDriverWait(driver, 20).until(lambda d: root.get_attribute("data-state") != "loading")
    assert root.get_attribute("data-state") == "ready", root.find_element(By.CSS_SELECTOR, "[data-status]").text
    driver.execute_script("arguments[0].scrollIntoView()", root)
    _shoot(driver, root, "render")

    # flip: the canvas shows the ground truth, other pixels
    before = _canvas(driver, root)
    root.find_element(By.CSS_SELECTOR, '[data-action="flip"]').click()
    assert root.get_attribute("data-shown") == "truth"
    flipped = _canvas(driver, root)
    assert np.abs(flipped.astype(int) - before).sum() > 0
    _shoot(driver, root, "flip-ground-truth")
    root.find_element(By.CSS_SELECTOR, '[data-action="flip"]').click()
    assert root.get_attribute("data-shown") == "render" and np.array_equal(_canvas(driver, root), before)

    # the exposure slider: ten steps of 0.1 EV up, a brighter image
    slider = root.find_element(By.CSS_SELECTOR, '[data-control="ev"]')
    ev0 = float(slider.get_attribute("value"))
    slider.send_keys(*[Keys.ARROW_RIGHT] * 10)
    ev = float(slider.get_attribute("value"))
    assert ev == pytest.approx(ev0 + 1.0)
    brighter = _canvas(driver, root)
    assert brighter.mean() > before.mean() + 1

    # the probe at a known pixel: both images' values and variances to float16 precision, z, the tile's p
    x, y = 5, 11
    centre = driver.execute_script("return arguments[0].harnessViewer.pixelCenter(arguments[1], arguments[2]);",
                                   root, x, y)
    canvas = root.find_element(By.CSS_SELECTOR, "[data-canvas]")
    ActionChains(driver).move_to_element_with_offset(canvas, int(centre["x"] - canvas.size["width"] / 2),
                                                     int(centre["y"] - canvas.size["height"] / 2)).perform()
    table = root.find_element(By.CSS_SELECTOR, "[data-probe-table]")
    assert (table.get_attribute("data-x"), table.get_attribute("data-y")) == (str(x), str(y))
    record = results["cases"][index]
    render = read_exr(record["render"]["exr"])
    truth = read_exr(record["ground_truth"]["path"])
    truth_variance = truth.variance if truth.variance is not None else np.zeros_like(truth.image)
    half = 2.0**-11  # float16's relative rounding
    np.testing.assert_allclose(_values(root, "render"), render.image[y, x], rtol=half, atol=0)
    np.testing.assert_allclose(_values(root, "truth"), truth.image[y, x], rtol=half, atol=0)
    np.testing.assert_allclose(_values(root, "render_var"), render.variance[y, x], rtol=2 * half + 1e-12, atol=0)
    np.testing.assert_allclose(_values(root, "truth_var"), truth_variance[y, x], rtol=2 * half, atol=0)
    z = (render.image[y, x] - truth.image[y, x]) / np.sqrt(render.variance[y, x] + truth_variance[y, x])
    np.testing.assert_allclose(_values(root, "pixel_z"), z, rtol=1e-2)
    pvalue = read_exr(record["verdict_maps"]["pvalue"]).image
    np.testing.assert_allclose(_values(root, "tile_p"), pvalue[y, x], rtol=1e-6, atol=1e-300)
    assert _values(root, "tile") == [y // 8, x // 8]
    # the canvas pixel there is the EXR pixel tone-mapped at that exposure (clamp sRGB), within float16's rounding
    at = _canvas(driver, root)[int(centre["y"]), int(centre["x"])]
    want = tonemap_srgb8(render.image[y:y + 1, x:x + 1], ev)[0, 0]
    assert np.abs(at.astype(int) - want).max() <= 1, (at, want)
    # the wheel zooms about the cursor: the probed pixel stays under it
    scale = driver.execute_script("return arguments[0].harnessViewer.view.scale;", root)
    origin = ScrollOrigin.from_element(canvas, int(centre["x"] - canvas.size["width"] / 2),
                                       int(centre["y"] - canvas.size["height"] / 2))
    ActionChains(driver).scroll_from_origin(origin, 0, -100).perform()
    zoomed = driver.execute_script("return arguments[0].harnessViewer.view.scale;", root)
    moved = driver.execute_script("return arguments[0].harnessViewer.pixelCenter(arguments[1], arguments[2]);",
                                  root, x, y)
    assert zoomed > scale and abs(moved["x"] - centre["x"]) <= zoomed and abs(moved["y"] - centre["y"]) <= zoomed
    _shoot(driver, root, "zoomed-probe")
    # swap on hover: the ground truth while the pointer is over the image
    root.find_element(By.CSS_SELECTOR, '[data-option="hover-swap"]').click()
    ActionChains(driver).move_to_element(canvas).perform()
    assert root.get_attribute("data-shown") == "truth"
    ActionChains(driver).move_to_element(table).perform()
    assert root.get_attribute("data-shown") == "render"
    root.find_element(By.CSS_SELECTOR, '[data-option="hover-swap"]').click()

    # every other mode draws something of its own
    seen = {}
    for mode in ("side", "error_signed", "error_relative", "tile_z", "pvalue", "flip_map"):
        root.find_element(By.CSS_SELECTOR, '[data-action="fit"]').click()
        root.find_element(By.CSS_SELECTOR, f'[data-mode="{mode}"]').click()
        assert root.get_attribute("data-shown") == mode
        seen[mode] = _canvas(driver, root)
        _shoot(driver, root, mode)
    assert seen["side"].shape[1] > before.shape[1]  # two panes
    maps = [seen[m] for m in ("error_signed", "error_relative", "tile_z", "pvalue", "flip_map")]
    assert all(not np.array_equal(a, b) for i, a in enumerate(maps) for b in maps[i + 1:])
    root.find_element(By.CSS_SELECTOR, '[data-control="curve"]').send_keys("f")  # the filmic curve
    root.find_element(By.CSS_SELECTOR, '[data-mode="render"]').click()
    assert not np.array_equal(_canvas(driver, root), brighter)

    errors = _errors(driver)
    assert not errors, errors

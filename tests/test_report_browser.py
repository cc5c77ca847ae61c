"""The report page in a real headless browser (Debian's chromium driven by selenium through chromedriver).

Every <img> must have decoded (naturalWidth > 0) and the console must hold no error. A page with one missing picture
is checked too, to show that the check does catch a broken page. Skips when chromium, chromedriver or selenium is
absent (`.ci/run` installs them).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from report_fixtures import make_outputs

pytestmark = pytest.mark.slow

CHROMIUM = os.environ.get("CVPIPE_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("CVPIPE_CHROMEDRIVER", "/usr/bin/chromedriver")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--window-size=1280,900"]
#: per <img>: source, finished loading, decoded width
IMAGES_JS = "return Array.from(document.images).map(i => [i.getAttribute('src'), i.complete, i.naturalWidth]);"


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium not installed (pip install -e '.[test]')")
    for exe in (CHROMIUM, CHROMEDRIVER):
        if not (os.path.isfile(exe) and os.access(exe, os.X_OK)):
            pytest.skip(f"{exe} not installed (apt-get install chromium chromium-driver)")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}")
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    # an explicit driver path keeps selenium from looking for (and downloading) a driver of its own
    driver = webdriver.Chrome(options=opts, service=Service(executable_path=CHROMEDRIVER))
    driver.set_page_load_timeout(20)
    try:
        yield driver
    finally:
        driver.quit()


def open_page(driver, page: Path) -> tuple[list, list]:
    """Load ``page``; return its images (src, complete, naturalWidth) and the console's SEVERE entries."""
    driver.get_log("browser")  # drop what an earlier page logged
    driver.get(page.resolve().as_uri())
    driver.execute_async_script(  # wait until every image has either loaded or failed
        "const done = arguments[arguments.length - 1];"
        "Promise.all(Array.from(document.images).map(i => i.complete ? null :"
        " new Promise(r => { i.onload = i.onerror = r; }))).then(() => done());"
    )
    errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    return driver.execute_script(IMAGES_JS), errors


def render(root: Path) -> Path:
    """Run the report stage in ``root`` (a fake repository) and return the page."""
    import runpy

    cwd, argv = os.getcwd(), sys.argv
    try:
        os.chdir(root)
        sys.argv = ["stages.report", "--outputs", "outputs", "--out", "outputs/report.html",
                    "--timings", "outputs/plots/timings.json"]
        try:
            runpy.run_module("stages.report", run_name="__main__")
        except SystemExit as exc:  # the stage runner always exits; 0 is success
            assert exc.code == 0, f"the report stage failed with exit {exc.code}"
    finally:
        os.chdir(cwd)
        sys.argv = argv
    return root / "outputs" / "report.html"


def test_generated_page_shows_every_picture_without_console_errors(browser, tmp_path):
    made = make_outputs(tmp_path, ("logo", "hough", "panorama"))
    images, errors = open_page(browser, render(tmp_path))
    assert len(images) == sum(len(s["pictures"]) for s in made) == 6
    assert all(complete and width > 0 for _, complete, width in images), images
    assert errors == []
    # the synthetic pictures are 320 and 160 pixels wide: the browser decoded the files themselves
    assert sorted({w for _, _, w in images}) == [160, 320]


def test_the_check_catches_a_missing_picture(browser, tmp_path):
    make_outputs(tmp_path, ("stereo",))
    page = render(tmp_path)
    (tmp_path / "outputs/stereo/result.png").unlink()  # deleted after the stage checked it
    images, errors = open_page(browser, page)
    broken = [src for src, _, width in images if width == 0]
    assert broken == ["stereo/result.png"]
    assert errors and any("result.png" in e["message"] for e in errors), errors


def test_real_report_in_the_browser(browser, repo_root, tmp_path):
    page = repo_root / "outputs" / "report.html"
    if not page.is_file():
        pytest.skip("outputs/report.html not built yet (dvc repro report)")
    images, errors = open_page(browser, page)
    assert all(complete and width > 0 for _, complete, width in images), [i for i in images if not i[2]]
    assert errors == []
    if os.environ.get("CVPIPE_REPORT_SCREENSHOT"):  # for a person to look at: the whole page as one PNG
        browser.save_screenshot(os.environ["CVPIPE_REPORT_SCREENSHOT"])


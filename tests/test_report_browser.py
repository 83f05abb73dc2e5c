"""The report in a real browser: Debian's headless chromium, driven by selenium, opens index.html of a
small real report (synthetic logs, one run with policy animations) and finds every image loaded, every
table there and no console error; with one image deleted, the same check fails.

Without chromium and chromium-driver (or selenium) the tests skip, naming what to install; under
CI=true they fail instead (.ci/run installs them)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from analysis.report import build_report
from analysis.synthetic import write_animation, write_run
from hersd.config import ScheduleConfig, TaskConfig, TrainConfig

CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run"]
EPOCHS = 8
TABLES = ("Summary per task and configuration", "Across tasks", "Runs")  # the h2 before each data table


def missing_browser() -> str | None:
    """What is missing to run the browser, as the line to install it; None if nothing is."""
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        return "no chromium: apt-get install chromium chromium-driver"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "no selenium: pip install -e '.[test]'"
    return None


@pytest.fixture
def browser(tmp_path):
    """A headless chromium with a new profile in a temporary folder, recording the console."""
    missing = missing_browser()
    if missing:
        if os.environ.get("CI") == "true":
            pytest.fail(f"{missing} (CI must run the browser test)")
        pytest.skip(missing)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in [*FLAGS, f"--user-data-dir={tmp_path / 'profile'}"]:
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=str(CHROMEDRIVER)), options=options)
    driver.set_page_load_timeout(60)
    yield driver
    driver.quit()


@pytest.fixture
def report(tmp_path) -> Path:
    """index.html of a report of FetchPush HER and a linear decay (2 seeds each, animations on every seed of
    HER and on seed 1 of the decay) and FetchReach HER (1 seed, no animation)."""
    logs = tmp_path / "logs"
    for schedule, successes in ((ScheduleConfig(), (0.3, 0.6)), (ScheduleConfig("linear", beta1=0.5), (0.5, 0.9))):
        for seed, success in enumerate(successes):
            run = logs / f"push/{schedule.kind}/seed{seed}"
            write_run(run, TrainConfig(task=TaskConfig(name="push"), schedule=schedule, seed=seed, epochs=EPOCHS),
                      np.linspace(0, success, EPOCHS))
            if schedule.kind == "constant" or seed == 1:
                write_animation(run, EPOCHS)
    write_run(logs / "reach/seed0", TrainConfig(task=TaskConfig(name="reach"), epochs=EPOCHS), np.full(EPOCHS, 0.9))
    return build_report(logs, tmp_path / "report", window=3, log=lambda line: None).index


def check_page(driver, index: Path) -> dict:
    """Open the page and assert what a reader needs: every <img> loaded (naturalWidth > 0), a table after each
    of TABLES with rows, no error in the console. Returns what it saw."""
    driver.get(index.as_uri())
    images = driver.execute_script(
        "return Array.from(document.images, i => ({src: i.getAttribute('src').slice(0, 80), "
        "loaded: i.complete && i.naturalWidth > 0}))")
    tables = driver.execute_script(
        "return Array.from(document.querySelectorAll('h2'), h => { let e = h.nextElementSibling;"
        " while (e && e.tagName !== 'TABLE' && e.tagName !== 'H2') e = e.nextElementSibling;"
        " return [h.textContent, e && e.tagName === 'TABLE' ? e.tBodies[0].rows.length : 0]; })")
    errors = [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]
    broken = [image["src"] for image in images if not image["loaded"]]
    rows = dict(tables)
    problems = [f"images not loaded: {broken}"] * bool(broken) + [f"console errors: {errors}"] * bool(errors)
    if not all(rows.get(title, 0) > 0 for title in TABLES):
        problems.append(f"a table is missing (heading: rows): {rows}")
    assert not problems, "; ".join(problems)
    return {"images": images, "rows": rows}


def test_every_image_loads_every_table_is_there_and_the_console_is_clean(browser, report):
    seen = check_page(browser, report)
    animations = [image["src"] for image in seen["images"] if image["src"].startswith("figures/animations/")]
    assert animations == ["figures/animations/push_0_HER_seed0_epoch8.gif",  # two seeds: a tie, the lower
                          "figures/animations/push_1_linear_b1=0.5_seed1_epoch8.gif"]
    assert len(seen["images"]) > len(animations)  # the figures, embedded
    assert seen["rows"]["Runs"] == 5


def test_a_missing_image_fails_the_check(browser, report):
    gone = next((report.parent / "figures/animations").glob("push_1_*.gif"))
    gone.unlink()
    with pytest.raises(AssertionError, match=rf"images not loaded: \['figures/animations/{gone.name}'\]; "
                                             rf"console errors: \[.*{gone.name} - Failed to load resource: "
                                             r"net::ERR_FILE_NOT_FOUND"):
        check_page(browser, report)
    shutil.copyfile(next((report.parent / "figures/animations").glob("push_0_*.gif")), gone)
    check_page(browser, report)  # back in place: the same page passes


def test_the_committed_report_loads_in_the_browser_with_its_policy_animations(browser):
    """results/report/index.html as committed (`hersd-report results/`): every figure and animation loads,
    every table is there, and the FetchPush campaign's policies are among the images."""
    seen = check_page(browser, Path(__file__).resolve().parent.parent / "results" / "report" / "index.html")
    animations = [image["src"] for image in seen["images"] if image["src"].startswith("figures/animations/push_")]
    assert len(animations) >= 2, seen["images"]

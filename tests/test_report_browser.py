"""The report in a real browser: Debian's headless chromium, driven by selenium, opens index.html of a
small real report (synthetic logs, one run with policy animations) in a 1280-px window and finds every image
loaded, every table there, no console error, no word broken inside a table cell, no table wider than the
window and the run list (collapsed) shorter than the window; with one image deleted, or a column narrowed
until its words break, the same check fails.

Without chromium and chromium-driver (or selenium) the tests skip, naming what to install; under
CI=true they fail instead (.ci/run installs them)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from analysis.figures import SMALLEST_FONT
from analysis.report import DPI, build_report
from analysis.synthetic import write_animation, write_run
from hersd.contract.config import TaskConfig, TrainConfig
from hersd.contract.schedules import Constant, Exponential, Linear, Success

CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run"]
WINDOW = (1280, 1000)  # width, height in CSS pixels
EPOCHS = 8
TABLES = ("Summary per task and configuration", "Across tasks", "Runs")  # the h2 before each data table
MIN_TEXT_PX = 9  # the smallest text of a figure (SMALLEST_FONT points at DPI) as rendered, in CSS pixels
# Each figure's rendered width over its natural (PNG) width: its smallest text in pixels is that share of
# SMALLEST_FONT points at DPI.
FIGURE_SCALES = ("return Array.from(document.querySelectorAll('figure img'), i => "
                 "[i.closest('figure').id, i.naturalWidth ? i.getBoundingClientRect().width / i.naturalWidth : 1])")
# Every word (run of non-space characters) of every table cell, its details opened: a word whose characters
# lie on more than one line (Range.getClientRects: one rectangle per line fragment) is broken inside the cell.
BROKEN_WORDS = """
document.querySelectorAll('details').forEach(d => { d.open = true; });
const broken = [];
for (const cell of document.querySelectorAll('table td, table th')) {
  const walker = document.createTreeWalker(cell, NodeFilter.SHOW_TEXT);
  for (let node = walker.nextNode(); node; node = walker.nextNode()) {
    for (const word of node.data.matchAll(/\\S+/g)) {
      const range = document.createRange();
      range.setStart(node, word.index);
      range.setEnd(node, word.index + word[0].length);
      const lines = new Set(Array.from(range.getClientRects(), r => Math.round(r.top)));
      if (lines.size > 1) broken.push(word[0]);
    }
  }
}
const wide = Array.from(document.querySelectorAll('table'), t => Math.round(t.getBoundingClientRect().right))
  .filter(right => right > document.documentElement.clientWidth);
document.querySelectorAll('details').forEach(d => { d.open = false; });
const runs = Array.from(document.querySelectorAll('h2')).find(h => h.textContent === 'Runs');
return {broken: broken, wide: wide, width: document.documentElement.clientWidth, height: window.innerHeight,
        runs: runs ? Math.round(document.documentElement.scrollHeight - runs.getBoundingClientRect().top
                                 - window.scrollY) : 0};
"""


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
    for flag in [*FLAGS, f"--user-data-dir={tmp_path / 'profile'}", f"--window-size={WINDOW[0]},{WINDOW[1]}"]:
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=str(CHROMEDRIVER)), options=options)
    driver.set_page_load_timeout(60)
    yield driver
    driver.quit()


@pytest.fixture
def report(tmp_path) -> Path:
    """index.html of a report of FetchPush HER and a linear decay (2 seeds each, animations on every seed of
    HER and on seed 1 of the decay; 2 more seeds of the decay in progress at epoch 5, one of them with its log
    cut short), an exponential and a success-driven decay (1 seed each: four composition panels) and FetchReach
    HER (1 seed, no animation)."""
    logs = tmp_path / "logs"
    for schedule, successes in ((Constant(), (0.3, 0.6)), (Linear(beta1=0.5), (0.5, 0.9)),
                                (Exponential(beta1=0.5, beta2=0.5), (0.7,)),
                                (Success(beta1=0.5), (0.8,))):
        for seed, success in enumerate(successes):
            run = logs / f"push/{schedule.kind}/seed{seed}"
            write_run(run, TrainConfig(task=TaskConfig(name="push"), schedule=schedule, seed=seed, epochs=EPOCHS),
                      np.linspace(0, success, EPOCHS))
            if schedule.kind == "constant" or (schedule.kind == "linear" and seed == 1):
                write_animation(run, EPOCHS)
    for seed in (2, 3):
        log = write_run(logs / f"push/linear/seed{seed}", TrainConfig(
            task=TaskConfig(name="push"), schedule=Linear(beta1=0.5), seed=seed, epochs=EPOCHS),
            np.linspace(0, 0.4, 5), complete=False)
        if seed == 3:  # the file cut short (or an earlier-format log of a running run): no valid end
            os.truncate(log, log.stat().st_size - 1)
    write_run(logs / "reach/seed0", TrainConfig(task=TaskConfig(name="reach"), epochs=EPOCHS), np.full(EPOCHS, 0.9))
    return build_report(logs, tmp_path / "report", window=3, log=lambda line: None).index


def check_layout(driver, legibility: bool = True) -> dict:
    """The open page's layout, as problems: words broken inside a table cell, tables wider than the window,
    a run list (its details closed) taller than the window, with ``legibility`` a figure whose smallest text
    renders below MIN_TEXT_PX (an image not loaded counts as full size: check_page names it)."""
    seen = driver.execute_script(BROKEN_WORDS)
    assert seen["width"] <= WINDOW[0] and seen["width"] > 0.9 * WINDOW[0], seen  # the window is 1280 px wide
    problems = [f"words broken inside table cells: {seen['broken']}"] * bool(seen["broken"])
    problems += [f"tables wider than the {seen['width']}-px window (right edges {seen['wide']})"] * bool(seen["wide"])
    problems += [f"the run list is {seen['runs']} px tall, more than the window's {seen['height']}"] * (
        seen["runs"] > seen["height"])
    smallest = {name: round(scale * SMALLEST_FONT * DPI / 72, 1) for name, scale in driver.execute_script(FIGURE_SCALES)}
    small = {name: size for name, size in smallest.items() if size < MIN_TEXT_PX}
    problems += [f"figures whose smallest text renders below {MIN_TEXT_PX} px: {small}"] * (bool(small) and legibility)
    seen["smallest_text"] = smallest
    return {"problems": problems, **seen}


def check_page(driver, index: Path, legibility: bool = True) -> dict:
    """Open the page and assert what a reader needs: every <img> loaded (naturalWidth > 0), a table after each
    of TABLES with rows, no error in the console, and a layout without problems (check_layout). Returns what it
    saw."""
    driver.get(index.as_uri())
    images = driver.execute_script(
        "return Array.from(document.images, i => ({src: i.getAttribute('src').slice(0, 80), "
        "loaded: i.complete && i.naturalWidth > 0}))")
    tables = driver.execute_script(  # the body rows of the tables between each h2 and the next (in details too)
        "return Array.from(document.querySelectorAll('h2'), h => { let rows = 0;"
        " for (let e = h.nextElementSibling; e && e.tagName !== 'H2'; e = e.nextElementSibling)"
        "  for (const t of (e.tagName === 'TABLE' ? [e] : e.querySelectorAll('table'))) rows += t.tBodies[0].rows.length;"
        " return [h.textContent, rows]; })")
    errors = [entry["message"] for entry in driver.get_log("browser") if entry["level"] == "SEVERE"]
    broken = [image["src"] for image in images if not image["loaded"]]
    rows = dict(tables)
    problems = [f"images not loaded: {broken}"] * bool(broken) + [f"console errors: {errors}"] * bool(errors)
    if not all(rows.get(title, 0) > 0 for title in TABLES):
        problems.append(f"a table is missing (heading: rows): {rows}")
    layout = check_layout(driver, legibility)
    problems += layout["problems"]
    assert not problems, "; ".join(problems)
    return {"images": images, "rows": rows, "layout": layout}


def test_every_image_loads_every_table_is_there_and_the_console_is_clean(browser, report):
    seen = check_page(browser, report)
    animations = [image["src"] for image in seen["images"] if image["src"].startswith("figures/animations/")]
    assert animations == ["figures/animations/push_0_HER_seed0_epoch8.gif",  # two seeds: a tie, the lower
                          "figures/animations/push_1_linear_b1=0.5_seed1_epoch8.gif"]
    assert len(seen["images"]) > len(animations)  # the figures, embedded
    assert seen["rows"]["Runs"] == 9


def test_the_run_list_is_grouped_by_configuration_and_says_each_state_in_words(browser, report):
    check_page(browser, report)
    groups = browser.execute_script(
        "return Array.from(document.querySelectorAll('details.runs'), d => [d.open, d.querySelector('summary')"
        ".textContent, Array.from(d.querySelectorAll('tbody tr'), r => r.cells[2].textContent)])")
    assert [(opened, line.split(":")[0]) for opened, line, _ in groups] == [
        (False, "FetchReach · HER"), (False, "FetchPush · HER"), (False, "FetchPush · linear b1=0.5"),
        (False, "FetchPush · exp b1=0.5 b2=0.5"), (False, "FetchPush · success b1=0.5")]
    assert groups[2][1] == ("FetchPush · linear b1=0.5: 4 runs, 2 complete, 2 in progress; test success at epoch 8, "
                            "median over the complete seeds 0.600")
    assert groups[2][2] == ["complete", "complete", "in progress (epoch 5 of 8)",
                            "in progress (epoch 5 of 8), log without a valid end"]
    headers = browser.execute_script("return Array.from(document.querySelectorAll('details.runs')[2]"
                                     ".querySelectorAll('th'), h => h.textContent)")
    assert headers[:4] == ["run folder", "seed", "state", "test success at its last epoch (smoothed)"]
    cells = browser.execute_script("return Array.from(document.querySelectorAll('details.runs td'), c => c.textContent)")
    assert "damaged" not in headers and not {"True", "False"} & set(cells)


def test_a_word_broken_inside_a_cell_fails_the_check(browser, report):
    """The layout check measures: narrowed to 2 em and allowed to break anywhere, the configuration column breaks
    its labels inside words, and the check names them; a table forced wider than the window fails it too."""
    check_page(browser, report)
    browser.execute_script("const style = document.createElement('style'); style.textContent = "
                           "'table.data td.text{max-width:2em;overflow-wrap:anywhere}'; document.head.append(style)")
    problems = check_layout(browser)["problems"]
    assert len(problems) == 1 and problems[0].startswith("words broken inside table cells: [")
    assert "'FetchReach'" in problems[0] and "'FetchPush'" in problems[0]
    browser.execute_script("document.querySelector('table.data').style.minWidth = '1400px'")
    assert "tables wider than the" in check_layout(browser)["problems"][-1]


def test_every_figure_keeps_its_text_legible_and_a_thumbnail_fails_the_check(browser, report):
    """At 1280 px every figure's smallest text (the four FetchPush composition panels' included) renders at
    MIN_TEXT_PX or more; shrunk to a thumbnail, the figure fails the check."""
    seen = check_page(browser, report)["layout"]["smallest_text"]
    assert {"schedules", "composition_push", "curves_push_lr1_lh1"} <= set(seen), seen
    browser.execute_script("document.querySelector('#composition_push img').style.width = '45%'")
    (problem,) = check_layout(browser)["problems"]
    assert problem.startswith(f"figures whose smallest text renders below {MIN_TEXT_PX} px: {{'composition_push'")


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
    every table is there, and the FetchPush campaign's policies are among the images. Its figures' text size is
    not checked: the committed page predates the two-panel figures (four panels a row), until the next
    `hersd-report results/` rewrites it."""
    seen = check_page(browser, Path(__file__).resolve().parent.parent / "results" / "report" / "index.html",
                      legibility=False)
    animations = [image["src"] for image in seen["images"] if image["src"].startswith("figures/animations/push_")]
    assert len(animations) >= 2, seen["images"]

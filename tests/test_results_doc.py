"""docs/RESULTS.md and results/README.md keep provenance where it is generated: no commit id or resume epoch
typed in their prose (quoted commands and code blocks may name them); every section of docs/RESULTS.md that
other docs point readers to exists."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
COMMIT_ID = re.compile(r"\b(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b")  # hex with a digit and a letter
RESUME_EPOCH = re.compile(r"(resum\w*[^.;]{0,60}?|checkpoints? after )\bepochs? \d", re.IGNORECASE)


def prose(markdown: str) -> list[str]:
    """The lines of ``markdown`` outside fenced and indented code blocks, with inline `code` removed."""
    lines, fenced = [], False
    for line in markdown.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced or line.startswith("    "):
            continue
        lines.append(re.sub(r"`[^`]*`", "`code`", line))
    return lines


def test_prose_checks_find_a_commit_id_and_a_resume_epoch_but_not_in_quoted_commands():
    sample = "Ran at commit 1a2b3c4d, resumed from the checkpoint after epoch 85.\n`git show 88641a8:x`\n    git log 3fd1fd7\n"
    text = "\n".join(prose(sample))
    assert COMMIT_ID.findall(text) == ["1a2b3c4d"] and RESUME_EPOCH.search(text)
    assert RESUME_EPOCH.search("from epoch 1 and from their checkpoints after epochs 101 / 94")
    assert not COMMIT_ID.search("\n".join(prose(sample.split("\n", 1)[1]))), "quoted commands are allowed"


@pytest.mark.parametrize("doc", ["docs/RESULTS.md", "results/README.md"])
def test_results_prose_types_no_commit_id_and_no_resume_epoch(doc):
    lines = prose((ROOT / doc).read_text(encoding="utf-8"))
    commits = [line for line in lines if COMMIT_ID.search(line)]
    resumes = [line for line in lines if RESUME_EPOCH.search(line)]
    assert not commits, f"commit ids belong in results/report/tables/runs_provenance.csv: {commits[:3]}"
    assert not resumes, f"resume epochs belong in results/report/tables/runs_provenance.csv: {resumes[:3]}"


def test_the_results_sections_other_docs_name_exist():
    headings = [line.lstrip("#").strip() for line in (ROOT / "docs/RESULTS.md").read_text(encoding="utf-8").splitlines()
                if line.startswith("#")]
    for name in ("The paper's claims, measured", "Reproduction: FetchPush", "Decay or mean rate",
                 "Reproduction: FetchPickAndPlace", "Reproduction: FetchSlide", "Denormals"):
        assert any(heading.startswith(name) for heading in headings), name

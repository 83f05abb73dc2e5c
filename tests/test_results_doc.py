"""docs/RESULTS.md and results/README.md keep provenance where it is generated: no commit id or resume epoch
typed in their prose (quoted commands and code blocks may name them); every section of docs/RESULTS.md that
other docs point readers to exists; no one-sided p whose direction no claim fixed before the data."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
COMMIT_ID = re.compile(r"\b(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b")  # hex with a digit and a letter
# What fixes a one-sided test's direction before the data: the paper's claims (the decay does better than a fixed
# rate: "for the decay", "for the linear", "for the exponential", "the paper's direction"), a one-sided hypothesis
# registered before its runs (its id, docs/registered.csv); else the sentence says it is exploratory.
PAPER_DIRECTION = r"for the (?:linear|exponential|decay)\b|the paper's direction|exploratory"
# Arms against which the paper fixes no direction (it reads the decay and its mean rate alike; the success-driven rate
# is beyond it): a one-sided p naming one needs a registered hypothesis or "exploratory", not the paper's direction.
NO_PAPER_DIRECTION = re.compile(r"\bcontrol\b|mean rate|0\.874375|success-driven", re.IGNORECASE)
GENERATED_BLOCK = re.compile(r"<!-- ([\w-]+)\b.*?-->.*?<!-- /\1 -->", re.DOTALL)
ONE_SIDED = re.compile(r"one[- ]sided", re.IGNORECASE)
P_VALUE = re.compile(r"\bp\s*(?:=|<|>|≤|≈)|\bp-values?\b|\bp of \d", re.IGNORECASE)  # p = 0.03, p < 0.05, p of 0.03
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


def one_sided_directions(paper: bool = True) -> re.Pattern:
    """What may follow a one-sided p in the same sentence: PAPER_DIRECTION (unless ``paper`` is False: only
    "exploratory") or a registered one-sided hypothesis's id."""
    from analysis.claims import registered_hypotheses

    ids = [re.escape(h.claim.registered) for h in registered_hypotheses() if not h.claim.two_sided]
    return re.compile("|".join([PAPER_DIRECTION if paper else "exploratory", *ids]), re.IGNORECASE)


def undirected_one_sided(markdown: str) -> list[str]:
    """The prose sentences and hand-written table rows of ``markdown`` (outside generated blocks, headings and code)
    that give a p as one-sided without what fixed its direction (:func:`one_sided_directions`)."""
    lines = [line for line in prose(GENERATED_BLOCK.sub("", markdown)) if not line.lstrip().startswith(("#", "<!--"))]
    rows = [line for line in lines if line.lstrip().startswith("|")]
    text = " ".join(" ".join(line for line in lines if line not in rows).split())
    sentences = re.split(r"(?<=[.!?])\s+(?=[A-Z(\"])", text)
    fixed, registered = one_sided_directions(), one_sided_directions(paper=False)
    return [unit for unit in sentences + rows if ONE_SIDED.search(unit) and P_VALUE.search(unit)
            and not (registered if NO_PAPER_DIRECTION.search(unit) else fixed).search(unit)]


@pytest.mark.parametrize("doc", ["docs/RESULTS.md", "README.md", "results/README.md"])
def test_every_one_sided_p_says_the_claim_that_fixed_its_direction(doc):
    """A one-sided p whose direction the data chose doubles its evidence: report it two-sided or exploratory."""
    assert undirected_one_sided((ROOT / doc).read_text(encoding="utf-8")) == []


def test_a_planted_one_sided_p_without_a_claim_is_refused_and_one_with_its_claim_is_not():
    text = (ROOT / "docs/RESULTS.md").read_text(encoding="utf-8")
    planted = "The control even ends below HER (median 0.563 against 0.691, one-sided p = 0.028)."
    assert undirected_one_sided(text + "\n" + planted + "\n") == [planted]
    for fixed in ("one-sided p = 0.028, exploratory", "one-sided p = 0.028, as order-final registered"):
        assert undirected_one_sided(text + "\n" + planted.replace("one-sided p = 0.028", fixed) + "\n") == []
    paper = "Linear 0.25 ends above HER (median 0.929 against 0.691, one-sided p = 0.099 for the decay)."
    assert undirected_one_sided(text + "\n" + paper + "\n") == []
    for variant in ("HER learns sooner (p < 0.01, one sided).", "HER learns sooner, a one-sided p of 0.004."):
        assert undirected_one_sided(text + "\n" + variant + "\n") == [variant]
    control = "Every linear seed ends above the control's, one-sided p = 0.004 for the decay doing better."
    assert undirected_one_sided(text + "\n" + control + "\n") == [control], "the paper fixes no direction there"
    assert undirected_one_sided(text + "\n" + control.replace("for the decay", "exploratory") + "\n") == []
    row = "| HER against linear 0.25 | one-sided permutation p = 0.028 |"
    assert undirected_one_sided(text + "\n" + row + "\n") == [row], "a hand-written table row is checked too"
    generated = "<!-- claims-table -->\n| a | b | one-sided p = 0.1: HER does better |\n<!-- /claims-table -->\n"
    assert undirected_one_sided(generated + "`one-sided p = 0.1`\n") == [], "generated tables give both directions"

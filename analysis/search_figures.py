"""Figures and tables of an Optuna beta search (``hersd-search``).

- ``<study>_beta_plane.png``: every trial in the (beta1, beta2) plane over the mu_eps
  iso-lines of eq. 11 (mu_eps = 1 - beta1 / (1 + exp(beta2))) with the band
  hersd.contract.schedules.MU_EPS_BAND (0.8 <= mu_eps <= 0.889) shaded (the seed paper's Fig. 12 region); complete trials are
  filled dots coloured by their objective, pruned ones open circles coloured by their last
  report, failed ones crosses; the best trial is starred. Linear-schedule trials sit on
  beta2 = 0; constant-schedule trials have no place in the plane and are only counted.
- ``<study>_best_trials.csv`` / ``.md``: the best complete trials, with mu_eps exact over
  the study's epochs (eq. 10) and by eq. 11, and their run directories.

What a study holds (trial parameters, user attributes) is defined by :mod:`hersd.contract.study`.
:func:`study_figures` draws these for every study in a storage (or one), opened read-only
by :func:`analysis.studies.open_study_storage`; ``python -m analysis.search_figures STORAGE OUT_DIR
[--study NAME]`` does the same from the command line (``hersd-report`` draws them for every
study it finds). Needs optuna, pandas and matplotlib, not torch or MuJoCo.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import optuna  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib import colormaps  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from optuna.trial import TrialState  # noqa: E402

from analysis.tables import markdown_table  # noqa: E402
from hersd.contract.config import ConfigError  # noqa: E402
from hersd.contract.schedules import MU_EPS_BAND, known_kinds, mean_rate_approx, schedule_class  # noqa: E402
from analysis.studies import open_study_storage  # noqa: E402
from hersd.contract.study import (KIND_ATTR, PARAM_NAMES, RETRY_OF_ATTR, RUN_DIRS_ATTR, StudySettings,  # noqa: E402
                         StudyStorageError, kind_params, mean_rates, schedule_config, trial_params)

ISO_LEVELS = (0.5, 0.6, 0.7, *MU_EPS_BAND, 0.95)  # mu_eps iso-lines drawn; the band's bounds thicker
DEFAULT_BETA2_RANGE = (-2.0, 2.0)
PLANE_KINDS = tuple(kind for kind in known_kinds() if "beta1" in kind_params(kind))  # eq. 9 decays
COLUMNS = ["trial", "state", "value", *PARAM_NAMES, "mu_eps", "mu_eps_approx", "in_band", "last_step", "retry_of",
           "duration_s", "run_dirs"]


def schedule_known(kind: str | None) -> bool:
    """Whether a trial's kind names a schedule class this process can import (a user's module may be missing)."""
    try:
        return kind is not None and schedule_class(kind) is not None
    except ConfigError:
        return False


def trials_frame(study: optuna.Study) -> pd.DataFrame:
    """One row per trial (waiting trials left out); mu_eps exact over the study's epochs."""
    settings = StudySettings.of(study.user_attrs)
    epochs = settings.epochs if settings else None
    rows = []
    for trial in study.get_trials(deepcopy=False):
        if trial.state == TrialState.WAITING:
            continue
        params = trial_params(trial.params, trial.user_attrs.get(KIND_ATTR))
        kind = params["kind"]
        decays = kind in PLANE_KINDS
        row = {"trial": trial.number, "state": trial.state.name.lower(), "value": trial.value, "kind": kind,
               "beta1": params.get("beta1"),
               "beta2": getattr(schedule_config(params), "beta2", None) if decays else None,
               "eps": params.get("eps"), "lambda_h": params.get("lambda_h"), "last_step": trial.last_step,
               "retry_of": trial.user_attrs.get(RETRY_OF_ATTR),
               "duration_s": trial.duration.total_seconds() if trial.duration is not None else None,
               "run_dirs": ";".join(trial.user_attrs.get(RUN_DIRS_ATTR, []))}
        if schedule_known(kind) and set(kind_params(kind)) <= set(params):
            exact, approx = mean_rates(params, epochs or 1)
            row.update(mu_eps=exact if epochs else np.nan, mu_eps_approx=approx,
                       in_band=MU_EPS_BAND[0] <= approx <= MU_EPS_BAND[1])
        rows.append(row)
    return pd.DataFrame.from_records(rows, columns=COLUMNS).astype(
        {name: "float64" for name in ("value", "beta1", "beta2", "eps", "lambda_h", "mu_eps", "mu_eps_approx",
                                      "duration_s")})


def best_trials(frame: pd.DataFrame, top: int = 10) -> pd.DataFrame:
    """The ``top`` complete trials by value, best first, with a rank column; empty columns dropped."""
    best = frame[frame["state"] == "complete"].sort_values(["value", "trial"], ascending=[False, True]).head(top)
    best = best.drop(columns=["state", "last_step"])
    if not best.empty:
        best = best.dropna(axis=1, how="all")
    best.insert(0, "rank", range(1, len(best) + 1))
    return best.reset_index(drop=True)


def _beta2_range(study: optuna.Study, frame: pd.DataFrame) -> tuple[float, float]:
    bounds = [(d.low, d.high) for t in study.get_trials(deepcopy=False) for name, d in t.distributions.items()
              if name == "beta2"]
    if bounds:
        return min(low for low, _ in bounds), max(high for _, high in bounds)
    values = frame["beta2"].dropna()
    if values.empty:
        return DEFAULT_BETA2_RANGE
    return min(DEFAULT_BETA2_RANGE[0], values.min()), max(DEFAULT_BETA2_RANGE[1], values.max())


def plot_beta_plane(frame: pd.DataFrame, beta2_range: tuple[float, float], title: str,
                    value_label: str = "objective") -> Figure:
    """The trials over the eq. 11 iso-lines of mu_eps, the band shaded, coloured by value."""
    fig = Figure(figsize=(7.0, 5.0), layout="constrained")
    ax = fig.add_subplot()
    margin = 0.03 * (beta2_range[1] - beta2_range[0] or 1.0)  # keep markers on the bounds visible
    beta2_limits = (beta2_range[0] - margin, beta2_range[1] + margin)
    beta1_grid, beta2_grid = np.meshgrid(np.linspace(0.0, 1.0, 201), np.linspace(*beta2_limits, 201))
    mu = mean_rate_approx(beta1_grid, beta2_grid)
    ax.contourf(beta1_grid, beta2_grid, mu, levels=list(MU_EPS_BAND), colors=["tab:green"], alpha=0.18)
    lines = ax.contour(beta1_grid, beta2_grid, mu, levels=list(ISO_LEVELS), colors="0.45",
                       linewidths=[1.6 if level in MU_EPS_BAND else 0.8 for level in ISO_LEVELS])
    ax.clabel(lines, fmt=lambda level: f"{level:g}", fontsize=8)

    in_plane = frame[frame["kind"].isin(PLANE_KINDS) & frame["beta1"].notna()]
    scored = in_plane[in_plane["state"].isin(["complete", "pruned"])]
    finite = scored["value"][np.isfinite(scored["value"])]
    norm = Normalize(finite.min(), finite.max()) if not finite.empty else Normalize(0.0, 1.0)
    if norm.vmin == norm.vmax:  # one value (e.g. no success yet): a [0, 1] scale still reads right
        norm = Normalize(min(norm.vmin, 0.0), max(norm.vmax, 1.0))
    cmap = colormaps["viridis"]
    complete = in_plane[in_plane["state"] == "complete"]
    pruned = in_plane[in_plane["state"] == "pruned"]
    failed = in_plane[in_plane["state"] == "fail"]
    dots = ax.scatter(complete["beta1"], complete["beta2"], c=complete["value"], cmap=cmap, norm=norm, s=46,
                      edgecolors="black", linewidths=0.5, zorder=3)
    ax.scatter(pruned["beta1"], pruned["beta2"], facecolors="none", s=46, linewidths=1.6, zorder=3,
               edgecolors=[cmap(norm(v)) if np.isfinite(v) else "0.5" for v in pruned["value"]])
    ax.scatter(failed["beta1"], failed["beta2"], marker="x", color="tab:red", s=40, zorder=3)
    if not complete.empty:
        best = complete.loc[complete["value"].idxmax()]
        ax.scatter([best["beta1"]], [best["beta2"]], marker="*", s=320, facecolors="none", edgecolors="black",
                   linewidths=1.2, zorder=4)
    fig.colorbar(dots, ax=ax, label=value_label)

    band_label = rf"${MU_EPS_BAND[0]} \leq \mu_\epsilon \leq {MU_EPS_BAND[1]}$ (eq. 11)"
    handles = [Patch(facecolor="tab:green", alpha=0.18, label=band_label),
               Line2D([], [], color="0.45", lw=0.8, label=r"$\mu_\epsilon$ iso-lines (eq. 11)"),
               Line2D([], [], ls="", marker="o", color="0.5", mec="black", label=f"complete ({len(complete)})"),
               Line2D([], [], ls="", marker="o", mfc="none", mec="0.5", mew=1.6,
                      label=f"pruned ({len(pruned)}; colour: last report)"),
               Line2D([], [], ls="", marker="x", color="tab:red", label=f"failed ({len(failed)})"),
               Line2D([], [], ls="", marker="*", mfc="none", mec="black", ms=12, label="best")]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.0, -0.13), ncol=2, fontsize=8, frameon=False)
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(*beta2_limits)
    ax.set_xlabel(r"$\beta_1$ (eq. 9: final drop of the relabel rate)")
    ax.set_ylabel(r"$\beta_2$ (eq. 9: shape; 0 = linear)")
    others = len(frame) - len(in_plane)
    ax.set_title(title + (f"\n({others} trial(s) without beta1/beta2 not shown)" if others else ""), fontsize=10)
    return fig


@dataclass
class StudySummary:
    """One study, read: ``trials`` (:func:`trials_frame`), ``best`` (:func:`best_trials`), the
    label of its objective and the beta2 range of its search space."""

    name: str
    trials: pd.DataFrame
    best: pd.DataFrame
    value_label: str
    beta2_range: tuple[float, float]

    def beta_plane(self) -> Figure:
        return plot_beta_plane(self.trials, self.beta2_range, f"{self.name}: {len(self.trials)} trials",
                               self.value_label)

    def best_markdown(self) -> str:
        """The best trials as a Markdown document (run directories left out: too wide)."""
        return (f"# Best trials of study `{self.name}`\n\n{self.value_label}; mu_eps exact over the study's "
                f"epochs (eq. 10) and by eq. 11.\n\n"
                + markdown_table(self.best.drop(columns=["run_dirs"], errors="ignore"), float_format="{:.4g}")
                + ("" if len(self.best) else "\n(no complete trials yet)\n"))


def read_study(storage: optuna.storages.BaseStorage, name: str, top: int = 10) -> StudySummary:
    """Everything drawn of study ``name``, read once from ``storage`` (an opened, read-only storage)."""
    study = optuna.load_study(study_name=name, storage=storage)
    frame = trials_frame(study)
    settings = StudySettings.of(study.user_attrs)
    value_label = settings.value_label() if settings else "objective"
    return StudySummary(name=name, trials=frame, best=best_trials(frame, top), value_label=value_label,
                        beta2_range=_beta2_range(study, frame))


def study_figures(storage_url_or_db_path: str | Path, out_dir: str | Path, study_name: str | None = None,
                  top: int = 10) -> list[Path]:
    """Draw the beta-plane figure and the best-trials tables of each study in the storage
    (or only ``study_name``) into ``out_dir``; -> the files written.

    ``storage_url_or_db_path``: a SQLite file (``results/search/<study>.db``), a journal file, ``journal:<path>``
    or a SQLAlchemy URL, opened read-only (:func:`analysis.studies.open_study_storage`, which raises
    :class:`hersd.contract.study.StudyStorageError` for one it cannot read).
    """
    opened = open_study_storage(storage_url_or_db_path)
    if study_name is not None and study_name not in opened.study_names:
        raise StudyStorageError(f"{opened.shown}: no study named {study_name!r} "
                                f"(it holds: {', '.join(opened.study_names)})")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for name in [study_name] if study_name is not None else opened.study_names:
        study = read_study(opened.storage, name, top)
        figure_path = out_dir / f"{name}_beta_plane.png"
        study.beta_plane().savefig(figure_path, dpi=150)
        csv_path = out_dir / f"{name}_best_trials.csv"
        study.best.to_csv(csv_path, index=False)
        md_path = out_dir / f"{name}_best_trials.md"
        md_path.write_text(study.best_markdown(), encoding="utf-8")
        written += [figure_path, csv_path, md_path]
    return written


def main(argv: list[str] | None = None) -> int:
    """``python -m analysis.search_figures STORAGE OUT_DIR [--study NAME]``: draw, print the files."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m analysis.search_figures", description=study_figures.__doc__)
    parser.add_argument("storage")
    parser.add_argument("out_dir")
    parser.add_argument("--study", default=None)
    args = parser.parse_args(argv)
    try:
        paths = study_figures(args.storage, args.out_dir, study_name=args.study)
    except StudyStorageError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print("\n".join(str(path) for path in paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())

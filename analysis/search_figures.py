"""Figures and tables of an Optuna search (``hersd-search``), over whatever settings it searched.

- ``<study>_beta_plane.png``, for a search of eq. 9's decays alone: every trial in the (beta1, beta2) plane
  over the mu_eps iso-lines of eq. 11 (mu_eps = 1 - beta1 / (1 + exp(beta2))) with the band
  hersd.contract.schedules.MU_EPS_BAND (0.8 <= mu_eps <= 0.889) shaded (the seed paper's Fig. 12 region); complete trials are
  filled dots coloured by their objective, pruned ones open circles coloured by their last
  report, failed ones crosses; the best trial is starred. Linear-schedule trials sit on beta2 = 0.
- ``<study>_settings.png``, for a search of any other setting (an outside schedule's ``k0``, ``low``; the
  constant's ``eps``; ``lambda_h``): one panel per such setting, the objective against the setting's value
  over its searched range, in the same marks; below the plane when eq. 9's decays were searched too.
- ``<study>_best_trials.csv`` / ``.md``: the best complete trials with each searched setting's value, mu_eps
  exact over the study's epochs (eq. 10) and by eq. 11 (where the schedule knows them), and their run directories.

What a study holds (trial parameters, user attributes) is defined by :mod:`hersd.contract.study`.
:func:`study_figures` draws these for every study in a storage (or one), opened read-only
by :func:`analysis.studies.open_study_storage`; ``python -m analysis.search_figures STORAGE OUT_DIR
[--study NAME]`` does the same from the command line (``hersd-report`` draws them for every
study it finds). Needs optuna, pandas and matplotlib, not torch or MuJoCo.
"""

from __future__ import annotations

import io
import sys
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import optuna  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib import colormaps  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402
from optuna.distributions import IntDistribution  # noqa: E402
from optuna.trial import FrozenTrial, TrialState  # noqa: E402

from analysis.figures import LEGEND_SIZE, PANEL_SIZE, wrap  # noqa: E402
from analysis.tables import markdown_table  # noqa: E402
from hersd.contract.errors import ConfigError, DiskFullError  # noqa: E402
from hersd.contract.runlog import replace_file  # noqa: E402
from hersd.contract.schedules import MU_EPS_BAND, known_kinds, mean_rate_approx, schedule_class  # noqa: E402
from analysis.studies import open_study_storage  # noqa: E402
from hersd.contract.study import (KIND_ATTR, PAPER_SETTINGS, PARAM_NAMES, REWARD_PARAM, RETRY_OF_ATTR,  # noqa: E402
                                  RUN_DIRS_ATTR, StudySettings, StudyStorageError, kind_params, mean_rates,
                                  schedule_config, trial_params)

ISO_LEVELS = (0.5, 0.6, 0.7, *MU_EPS_BAND, 0.95)  # mu_eps iso-lines drawn; the band's bounds thicker
DEFAULT_BETA2_RANGE = (-2.0, 2.0)
PLANE_KINDS = tuple(kind for kind in known_kinds() if "beta1" in kind_params(kind))  # eq. 9 decays
PLANE_SETTINGS = ("beta1", "beta2")  # the plane's axes
COLUMNS = ["trial", "state", "value", *PARAM_NAMES, "mu_eps", "mu_eps_approx", "in_band", "last_step", "retry_of",
           "duration_s", "run_dirs"]  # the searched settings of other kinds follow PARAM_NAMES
PANEL_COLUMNS = 2  # setting panels per row: at 100 dpi two are ~900 px wide, legible in a 1280-px page
PLANE_SIZE = (7.0, 5.0)  # inches


@dataclass(frozen=True)
class SettingRange:
    """The range a study drew a setting from (the union over its trials): its axis in the setting's panel."""

    low: float
    high: float
    log: bool
    integer: bool  # drawn as a whole number (suggest_int)


def searched_settings(trials: list[FrozenTrial]) -> list[str]:
    """The settings a study's trials drew (their Optuna parameters but ``kind``): the paper's in PARAM_NAMES' order,
    then the others in the order the trials first drew them."""
    drawn = dict.fromkeys(name for trial in trials for name in trial.params if name != "kind")
    return [name for name in PARAM_NAMES if name in drawn] + [name for name in drawn if name not in PARAM_NAMES]


def setting_ranges(trials: list[FrozenTrial]) -> dict[str, SettingRange]:
    """Each numeric setting's range over the study's trials (their distributions' bounds, joined)."""
    ranges: dict[str, SettingRange] = {}
    for trial in trials:
        for name, dist in trial.distributions.items():
            if name == "kind" or not hasattr(dist, "low"):
                continue
            seen = ranges.get(name, SettingRange(dist.low, dist.high, dist.log, isinstance(dist, IntDistribution)))
            ranges[name] = SettingRange(min(seen.low, dist.low), max(seen.high, dist.high), seen.log, seen.integer)
    return ranges


def schedule_known(kind: str | None) -> bool:
    """Whether a trial's kind names a schedule class this process can import (a user's module may be missing)."""
    try:
        return kind is not None and schedule_class(kind) is not None
    except ConfigError:
        return False


def trials_frame(study: optuna.Study) -> pd.DataFrame:
    """One row per trial (waiting trials left out): PARAM_NAMES' columns, then a column per other searched
    setting (whole numbers as integers); mu_eps exact over the study's epochs."""
    settings = StudySettings.of(study.user_attrs)
    epochs = settings.epochs if settings else None
    trials = study.get_trials(deepcopy=False)
    others = [name for name in searched_settings(trials) if name not in PARAM_NAMES]
    ranges = setting_ranges(trials)
    rows = []
    for trial in trials:
        if trial.state == TrialState.WAITING:
            continue
        params = trial_params(trial.params, trial.user_attrs.get(KIND_ATTR))
        kind = params["kind"]
        decays = kind in PLANE_KINDS
        row = {"trial": trial.number, "state": trial.state.name.lower(), "value": trial.value, "kind": kind,
               "beta1": params.get("beta1"),
               "beta2": getattr(schedule_config(params), "beta2", None) if decays else params.get("beta2"),
               "eps": params.get("eps"), REWARD_PARAM: params.get(REWARD_PARAM),
               **{name: params.get(name) for name in others}, "last_step": trial.last_step,
               "retry_of": trial.user_attrs.get(RETRY_OF_ATTR),
               "duration_s": trial.duration.total_seconds() if trial.duration is not None else None,
               "run_dirs": ";".join(trial.user_attrs.get(RUN_DIRS_ATTR, []))}
        if schedule_known(kind) and set(kind_params(kind)) <= set(params):
            exact, approx = mean_rates(params, epochs or 1)
            row.update(mu_eps=exact if epochs else np.nan, mu_eps_approx=approx,
                       in_band=MU_EPS_BAND[0] <= approx <= MU_EPS_BAND[1] if np.isfinite(approx) else None)
        rows.append(row)
    at = COLUMNS.index(PARAM_NAMES[-1]) + 1
    types = {name: "Int64" if name in ranges and ranges[name].integer else "float64" for name in others}
    return pd.DataFrame.from_records(rows, columns=[*COLUMNS[:at], *others, *COLUMNS[at:]]).astype(
        {**{name: "float64" for name in ("value", *PAPER_SETTINGS, REWARD_PARAM, "mu_eps", "mu_eps_approx",
                                         "duration_s")}, **types})


def in_plane(frame: pd.DataFrame) -> pd.Series:
    """Which trials the (beta1, beta2) plane shows: those of eq. 9's decays."""
    return frame["kind"].isin(PLANE_KINDS) & frame["beta1"].notna()


def panel_settings(frame: pd.DataFrame, settings: list[str]) -> list[str]:
    """The searched settings the plane does not show, a panel each: every setting but beta1 and beta2, and those
    two where trials outside the plane have them."""
    outside = frame[~in_plane(frame)]
    return [name for name in settings if name in frame
            and (outside if name in PLANE_SETTINGS else frame)[name].notna().any()]


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


def value_norm(frame: pd.DataFrame) -> Normalize:
    """The colour scale of the trials' values (complete and pruned): their range, [0, 1] around a single value."""
    scored = frame[frame["state"].isin(["complete", "pruned"])]
    finite = scored["value"][np.isfinite(scored["value"])]
    norm = Normalize(finite.min(), finite.max()) if not finite.empty else Normalize(0.0, 1.0)
    if norm.vmin == norm.vmax:  # one value (e.g. no success yet): a [0, 1] scale still reads right
        norm = Normalize(min(norm.vmin, 0.0), max(norm.vmax, 1.0))
    return norm


def marker_handles(counts: dict[str, int]) -> list[Line2D]:
    """The legend entries of the trials' marks, with how many trials of each state are drawn."""
    return [Line2D([], [], ls="", marker="o", color="0.5", mec="black", label=f"complete ({counts['complete']})"),
            Line2D([], [], ls="", marker="o", mfc="none", mec="0.5", mew=1.6,
                   label=f"pruned ({counts['pruned']}; colour: last report)"),
            Line2D([], [], ls="", marker="x", color="tab:red", label=f"failed ({counts['fail']})"),
            Line2D([], [], ls="", marker="*", mfc="none", mec="black", ms=12, label="best")]


def plot_beta_plane(frame: pd.DataFrame, beta2_range: tuple[float, float], title: str,
                    value_label: str = "objective") -> Figure:
    """The trials over the eq. 11 iso-lines of mu_eps, the band shaded, coloured by value."""
    fig = Figure(figsize=PLANE_SIZE, layout="constrained")
    ax = draw_plane(fig, frame, beta2_range, value_label, value_norm(frame[in_plane(frame)]), best_trial(frame))
    others = int((~in_plane(frame)).sum())
    ax.set_title(title + (f"\n({others} trial(s) without beta1/beta2 not shown)" if others else ""), fontsize=10)
    return fig


def best_trial(frame: pd.DataFrame) -> int | None:
    """The number of the complete trial of the highest value (the first of equals), None before any."""
    complete = frame[(frame["state"] == "complete") & frame["value"].notna()]
    return None if complete.empty else int(complete.sort_values(["value", "trial"], ascending=[False, True])
                                           ["trial"].iloc[0])


def draw_plane(fig: Figure, frame: pd.DataFrame, beta2_range: tuple[float, float], value_label: str,
               norm: Normalize, best: int | None) -> Axes:
    """The (beta1, beta2) plane of ``frame``'s decays in ``fig`` (a figure or a subfigure), the best trial
    (number ``best``) starred if it is one of them -> its axes."""
    ax = fig.add_subplot()
    margin = 0.03 * (beta2_range[1] - beta2_range[0] or 1.0)  # keep markers on the bounds visible
    beta2_limits = (beta2_range[0] - margin, beta2_range[1] + margin)
    beta1_grid, beta2_grid = np.meshgrid(np.linspace(0.0, 1.0, 201), np.linspace(*beta2_limits, 201))
    mu = mean_rate_approx(beta1_grid, beta2_grid)
    ax.contourf(beta1_grid, beta2_grid, mu, levels=list(MU_EPS_BAND), colors=["tab:green"], alpha=0.18)
    lines = ax.contour(beta1_grid, beta2_grid, mu, levels=list(ISO_LEVELS), colors="0.45",
                       linewidths=[1.6 if level in MU_EPS_BAND else 0.8 for level in ISO_LEVELS])
    ax.clabel(lines, fmt=lambda level: f"{level:g}", fontsize=8)

    shown = frame[in_plane(frame)]
    cmap = colormaps["viridis"]
    complete, pruned, failed = (shown[shown["state"] == state] for state in ("complete", "pruned", "fail"))
    dots = ax.scatter(complete["beta1"], complete["beta2"], c=complete["value"], cmap=cmap, norm=norm, s=46,
                      edgecolors="black", linewidths=0.5, zorder=3)
    ax.scatter(pruned["beta1"], pruned["beta2"], facecolors="none", s=46, linewidths=1.6, zorder=3,
               edgecolors=[cmap(norm(v)) if np.isfinite(v) else "0.5" for v in pruned["value"]])
    ax.scatter(failed["beta1"], failed["beta2"], marker="x", color="tab:red", s=40, zorder=3)
    starred = complete[complete["trial"] == best]
    ax.scatter(starred["beta1"], starred["beta2"], marker="*", s=320, facecolors="none", edgecolors="black",
               linewidths=1.2, zorder=4)
    fig.colorbar(dots, ax=ax, label=value_label)

    band_label = rf"${MU_EPS_BAND[0]} \leq \mu_\epsilon \leq {MU_EPS_BAND[1]}$ (eq. 11)"
    handles = [Patch(facecolor="tab:green", alpha=0.18, label=band_label),
               Line2D([], [], color="0.45", lw=0.8, label=r"$\mu_\epsilon$ iso-lines (eq. 11)"),
               *marker_handles({"complete": len(complete), "pruned": len(pruned), "fail": len(failed)})]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.0, -0.13), ncol=2, fontsize=8, frameon=False)
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(*beta2_limits)
    ax.set_xlabel(r"$\beta_1$ (eq. 9: final drop of the relabel rate)")
    ax.set_ylabel(r"$\beta_2$ (eq. 9: shape; 0 = linear)")
    return ax


def draw_setting(ax: Axes, frame: pd.DataFrame, name: str, span: SettingRange | None, norm: Normalize,
                 best: int | None) -> None:
    """One setting's panel: each trial of ``frame`` that drew it, its value against the setting (failed trials,
    which have none, as crosses along the bottom), the best trial (number ``best``) starred."""
    cmap = colormaps["viridis"]
    shown = frame[frame[name].notna()]
    x = shown[name].astype(float)
    complete, pruned, failed = (shown["state"] == state for state in ("complete", "pruned", "fail"))
    ax.scatter(x[complete], shown["value"][complete], c=shown["value"][complete], cmap=cmap, norm=norm, s=46,
               edgecolors="black", linewidths=0.5, zorder=3)
    ax.scatter(x[pruned], shown["value"][pruned], facecolors="none", s=46, linewidths=1.6, zorder=3,
               edgecolors=[cmap(norm(v)) if np.isfinite(v) else "0.5" for v in shown["value"][pruned]])
    ax.scatter(x[failed], np.full(int(failed.sum()), 0.04), transform=ax.get_xaxis_transform(), marker="x",
               color="tab:red", s=40, zorder=3)
    starred = shown["trial"] == best
    ax.scatter(x[starred], shown["value"][starred], marker="*", s=320, facecolors="none", edgecolors="black",
               linewidths=1.2, zorder=4)
    if span is not None:
        if span.log:
            ax.set_xscale("log")
        margin = 0.04 * (span.high - span.low or 1.0)
        ax.set_xlim(*((span.low / 1.1, span.high * 1.1) if span.log else (span.low - margin, span.high + margin)))
        if span.integer:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    kinds = ", ".join(str(kind) for kind in dict.fromkeys(shown["kind"]))
    ax.set_title(wrap(f"{name} ({kinds}): {len(shown)} trial(s)", 48), fontsize=10)
    ax.set_xlabel(name)


def plot_settings(frame: pd.DataFrame, panels: list[str], ranges: dict[str, SettingRange],
                  beta2_range: tuple[float, float], title: str, value_label: str = "objective") -> Figure:
    """The objective against each of ``panels``' settings, a panel each, below the (beta1, beta2) plane when
    trials of eq. 9's decays are among ``frame``'s."""
    plane = bool(in_plane(frame).any())
    columns, rows = min(len(panels), PANEL_COLUMNS), -(-len(panels) // PANEL_COLUMNS)
    width, height = max(PLANE_SIZE[0] if plane else 0.0, columns * PANEL_SIZE[0]), rows * (PANEL_SIZE[1] + 0.4)
    fig = Figure(figsize=(width, height + (PLANE_SIZE[1] if plane else 0.9)), layout="constrained")
    norm = value_norm(frame)
    if plane:
        top, below = fig.subfigures(2, 1, height_ratios=[PLANE_SIZE[1], height])
        draw_plane(top, frame, beta2_range, value_label, norm, best_trial(frame)).set_title(title, fontsize=10)
    else:
        below = fig
        fig.suptitle(title, fontsize=10)
    axes = below.subplots(rows, columns, squeeze=False, sharey=True).ravel()
    outside = frame[~in_plane(frame)]
    for ax, name in zip(axes, panels):
        draw_setting(ax, outside if name in PLANE_SETTINGS else frame, name, ranges.get(name), norm,
                     best_trial(frame))
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    for ax in axes[::columns]:
        ax.set_ylabel(wrap(value_label, 30))
    if not plane:  # the plane's legend names the marks
        counts = frame["state"].value_counts()
        marks = marker_handles({state: int(counts.get(state, 0)) for state in ("complete", "pruned", "fail")})
        fig.legend(handles=marks, loc="outside lower center", ncol=min(4, 2 * columns), fontsize=LEGEND_SIZE,
                   frameon=False)  # one panel is too narrow for the four marks in a row
    return fig


@dataclass
class StudySummary:
    """One study, read: ``trials`` (:func:`trials_frame`), ``best`` (:func:`best_trials`), the
    label of its objective, the settings its trials drew, their ranges and the beta2 range of its search space."""

    name: str
    trials: pd.DataFrame
    best: pd.DataFrame
    value_label: str
    beta2_range: tuple[float, float]
    settings: list[str] = field(default_factory=list)  # searched_settings
    ranges: dict[str, SettingRange] = field(default_factory=dict)  # setting_ranges

    @property
    def panels(self) -> list[str]:
        """The searched settings the plane does not show (:func:`panel_settings`)."""
        return panel_settings(self.trials, self.settings)

    @property
    def figure_name(self) -> str:
        """The figure's file stem after the study's: ``beta_plane`` when the plane shows every searched setting,
        else ``settings``."""
        return "settings" if self.panels else "beta_plane"

    @property
    def figure_title(self) -> str:
        """What the figure shows, e.g. ``trials in the (β1, β2) plane``, ``trials against k0, low``."""
        plane, panels = bool(in_plane(self.trials).any()) or not self.panels, ", ".join(self.panels)
        return ("trials in the (β1, β2) plane" + (f" and against {panels}" if panels else "")) if plane \
            else f"trials against {panels}"

    def figure(self) -> Figure:
        """The (beta1, beta2) plane, or a panel per setting it does not show (below it, when it has trials)."""
        title = f"{self.name}: {len(self.trials)} trials"
        if not self.panels:
            return plot_beta_plane(self.trials, self.beta2_range, title, self.value_label)
        return plot_settings(self.trials, self.panels, self.ranges, self.beta2_range, title, self.value_label)

    def best_markdown(self) -> str:
        """The best trials as a Markdown document (run directories left out: too wide); its header names the
        mean rates its table has."""
        rates = [text for column, text in (("mu_eps", "exact over the study's epochs (eq. 10)"),
                                           ("mu_eps_approx", "by eq. 11")) if column in self.best]
        header = [self.value_label, *([f"searched settings: {', '.join(self.settings)}"] if self.settings else []),
                  *([f"mu_eps {' and '.join(rates)}"] if rates else [])]
        return (f"# Best trials of study `{self.name}`\n\n{'; '.join(header)}.\n\n"
                + markdown_table(self.best.drop(columns=["run_dirs"], errors="ignore"), float_format="{:.4g}")
                + ("" if len(self.best) else "\n(no complete trials yet)\n"))


def read_study(storage: optuna.storages.BaseStorage, name: str, top: int = 10) -> StudySummary:
    """Everything drawn of study ``name``, read once from ``storage`` (an opened, read-only storage)."""
    study = optuna.load_study(study_name=name, storage=storage)
    frame = trials_frame(study)
    settings = StudySettings.of(study.user_attrs)
    value_label = "objective" if settings is None else \
        f"{settings.objective} of {settings.metric}, mean of {settings.seeds} seed(s)"  # what a trial's value is
    trials = study.get_trials(deepcopy=False)
    return StudySummary(name=name, trials=frame, best=best_trials(frame, top), value_label=value_label,
                        beta2_range=_beta2_range(study, frame), settings=searched_settings(trials),
                        ranges=setting_ranges(trials))


def study_figures(storage_url_or_db_path: str | Path, out_dir: str | Path, study_name: str | None = None,
                  top: int = 10) -> list[Path]:
    """Draw the figure (the beta plane or the settings' panels) and the best-trials tables of each study in the
    storage (or only ``study_name``) into ``out_dir``; -> the files written.

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
        figure = io.BytesIO()
        study.figure().savefig(figure, format="png", dpi=150)
        files = {f"{name}_{study.figure_name}.png": figure.getvalue(),
                 f"{name}_best_trials.csv": study.best.to_csv(index=False).encode(),
                 f"{name}_best_trials.md": study.best_markdown().encode()}
        for file, data in files.items():  # each whole; a full disk: DiskFullError, the file and the bytes it needs
            replace_file(out_dir / file, data, sync=False)
            written.append(out_dir / file)
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
    except (StudyStorageError, DiskFullError) as err:  # one line: a storage it cannot read, a full disk
        print(f"error: {err}", file=sys.stderr)
        return 2
    print("\n".join(str(path) for path in paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())

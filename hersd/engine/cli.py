"""``hersd-train``: compose one run's config from the command line, run it, print its log's path.

``hersd-train task=push schedule=linear schedule.beta1=0.25 seed=0 epochs=50``; re-running
the same command resumes an interrupted run. ``--help`` is generated from the schema
(:mod:`hersd.contract.config`, each field's comment), the config groups under ``conf/`` and each schedule class
(the registered kinds, and a class of your own the command names: ``schedule._target_=<module>.<Class> --help``),
and a learner the command names beyond the package's (``learner._target_=<module>.<Class> --help``).

This module imports only the standard library and the contract's errors at its top; each function imports the
contract modules it uses (pandas, OmegaConf and Hydra among them), so a Ctrl-C while they load is inside
:func:`main`'s handling: one line, exit code 130, from the command's first moment.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hersd.contract.errors import ConfigError, DiskFullError, sigterm_as_ctrl_c

if TYPE_CHECKING:
    from hersd.contract.config import TrainConfig
    from hersd.contract.runspec import RunSpec

GROUPS = ("task", "algo", "schedule", "learner")  # config groups a run selects (conf/<group>/*.yaml)
HELP_FLAGS = ("-h", "--help")
DRY_RUN_FLAG = "--dry-run"  # print the resolved run (folder, identity, settings) and train nothing
_FIELD_LINE = re.compile(r"^\s+(\w+):[^=]+=.*?(?:#\s*(.*))?$")


def field_docs(schema: type) -> dict[str, str]:
    """Field name -> its documentation: the comment on the field's line, else the comment lines above it; a
    field a dataclass inherits keeps its parent's (a learner's settings subclassing TD3Config)."""
    docs: dict[str, str] = {}
    for cls in reversed([cls for cls in schema.__mro__ if dataclasses.is_dataclass(cls)]):
        docs.update(_own_field_docs(cls))
    return docs


def _own_field_docs(schema: type) -> dict[str, str]:
    """:func:`field_docs` of the fields a class's own source declares ({} when its source is not at hand)."""
    try:
        source = inspect.getsource(schema)
    except (OSError, TypeError):
        return {}
    docs: dict[str, str] = {}
    above: list[str] = []
    for line in source.splitlines():
        stripped = line.strip()
        if stripped.startswith("#"):
            above.append(stripped.lstrip("# "))
            continue
        match = _FIELD_LINE.match(line)
        if match:
            docs[match.group(1)] = match.group(2) or " ".join(above)
        above = []
    return docs


def schema_lines(schema: type, prefix: str = "") -> list[str]:
    """``key=default  doc`` for every field of a dataclass schema, nested ones flattened with dots."""
    from hersd.contract.config import PACKAGE_LEARNERS
    from hersd.contract.schedules import TARGET_KEY

    docs = field_docs(schema)
    lines = []
    defaults = schema()
    for item in dataclasses.fields(schema):
        value: Any = getattr(defaults, item.name)
        if item.name == "schedule":
            lines.append(f"  {prefix}schedule.kind={value.kind}".ljust(34) + "  the schedule (below), or "
                         f"schedule.{TARGET_KEY}=<module>.<Class>: a hersd.contract.schedules.Schedule of your own")
        elif item.name == "learner":  # its name, then each package learner's settings (docs/LEARNERS.md)
            lines.append(f"  {prefix}learner.name={value.name}".ljust(34) + f"  {docs.get(item.name, '')}")
            for name, settings in PACKAGE_LEARNERS.items():
                lines += schema_lines(settings, f"{prefix}learner.{name}.") if settings else []
        elif dataclasses.is_dataclass(value):
            lines += schema_lines(type(value), f"{prefix}{item.name}.")
        else:
            shown = "null" if value is None else str(value).lower() if isinstance(value, bool) else value
            lines.append(f"  {prefix}{item.name}={shown}".ljust(34) + f"  {docs.get(item.name, '')}")
    return lines


def schedule_lines(chosen: list[str] = ()) -> list[str]:
    """Each schedule kind's formula, then its settings (``schedule.<name>=default  doc``), as its class declares
    them; after the registered kinds, the classes ``chosen`` by path (``schedule._target_=<module>.<Class>``)."""
    from hersd.contract.schedules import known_kinds, schedule_class

    lines = []
    for kind in [*known_kinds(), *(path for path in chosen if path not in known_kinds())]:
        cls = schedule_class(kind)
        lines.append(f"  {kind}: {cls.formula or cls.__doc__.splitlines()[0]}")
        for item in cls.params():
            shown = "null" if item.default is None else item.default
            lines.append(f"    schedule.{item.name}={shown}".ljust(34) + f"  {item.metadata['doc']}")
    return lines


def chosen_schedules(argv: list[str]) -> list[str]:
    """The schedule classes a command line names by ``schedule._target_=`` or ``schedule.kind=``, or by a preset
    of one's own (``schedule=step`` in a ``hydra.searchpath`` folder): the class the composed config holds."""
    from hersd.contract.compose import group_choices
    from hersd.contract.schedules import TARGET_KEY, kind_name

    keys = (f"schedule.{TARGET_KEY}", "schedule.kind")
    named = [arg.split("=", 1)[1] for arg in argv if arg.split("=", 1)[0].lstrip("+") in keys]
    presets = [arg.split("=", 1)[1] for arg in argv if arg.split("=", 1)[0] == "schedule"]
    if any(preset not in group_choices("schedule") for preset in presets):
        named.append(kind_name(type(composed(argv).schedule)))
    return named


def composed(argv: list[str]) -> TrainConfig:
    """The run config of a --help command line (less the flag); ConfigError (one line) if it does not compose."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from hersd.contract.compose import compose_train, explain_config_error

    try:
        return compose_train([arg for arg in argv if arg not in HELP_FLAGS])
    except (HydraException, OmegaConfBaseException) as err:
        raise ConfigError(explain_config_error(err)) from None


def searched_folders(argv: list[str]) -> list[Path]:
    """The config folders of ``hydra.searchpath=[file://<folder>, ...]`` on the command line."""
    paths = [arg.split("=", 1)[1].strip("[]").split(",") for arg in argv if arg.startswith("hydra.searchpath=")]
    return [Path(path.strip().removeprefix("file://")) for group in paths for path in group
            if path.strip().startswith("file://")]


def choices(group: str, argv: list[str]) -> list[str]:
    """A group's choices: the package's (:func:`group_choices`), and the configs of the searched folders."""
    from hersd.contract.compose import group_choices

    own = [path.stem for folder in searched_folders(argv) for path in (folder / group).glob("*.yaml")]
    return sorted({*group_choices(group), *own})


def learner_lines(argv: list[str]) -> list[str]:
    """The settings (``learner.<key>.<field>=default  doc``) of each learner the command line names
    (``learner=``, ``learner.name=``, ``learner._target_=``) beyond the package's, whose settings the keys list."""
    from hersd.contract.compose import group_choices
    from hersd.contract.config import PACKAGE_LEARNERS, learner_key, learner_settings_class
    from hersd.contract.schedules import TARGET_KEY

    keys = ("learner", "learner.name", f"learner.{TARGET_KEY}")
    named = [name for arg in argv if arg.split("=", 1)[0].lstrip("+") in keys for name in arg.split("=", 1)[1].split(",")]
    presets = [arg.split("=", 1)[1] for arg in argv if arg.split("=", 1)[0] == "learner"]
    if any(preset not in group_choices("learner") for preset in presets):  # a config of one's own: its learner
        named = [name for name in named if name not in presets] + [composed(argv).learner.name]
    lines = []
    for name in dict.fromkeys(named):
        if name in PACKAGE_LEARNERS:
            continue
        recorded, settings = learner_settings_class(name)
        lines.append(f"  {recorded}:" + ("" if settings else " no settings"))
        lines += schema_lines(settings, f"  learner.{learner_key(recorded)}.") if settings else []
    return ["", "learners named on the command line (their settings):", *lines] if lines else []


def update_path_lines() -> list[str]:
    """The update paths (precision x update) and whether this CPU runs each: the bf16 ones need bf16
    instructions (docs/LEARNERS.md, "Precision"; their speed per CPU model: docs/RESULTS.md, "Speed")."""
    from hersd.contract.config import FAST_UPDATE_LEARNERS
    from hersd.engine.resources import cpu_has_bf16

    bf16 = "yes" if cpu_has_bf16() else "no: this CPU has no bf16 instructions (refused in one line)"
    fast = f"update=fast ({', '.join(FAST_UPDATE_LEARNERS)})"
    paths = [("fp32 autograd", "the default", "yes"), ("fp32 fast", fast, "yes"),
             ("bf16 autocast", "precision=bf16", bf16), ("bf16 fast", f"precision=bf16 {fast}", bf16)]
    return ["update paths (precision x update; each a run identity of its own) and whether this CPU runs them:",
            *(f"  {name:<14} {command:<38} {runs}" for name, command, runs in paths)]


def usage(argv: list[str] = ()) -> str:
    """The --help text; an outside schedule class the command line names (``schedule._target_=...``) is listed
    with the package's kinds, and a learner it names beyond the package's with its settings (ConfigError if
    either cannot be found)."""
    from hersd.contract.config import TrainConfig

    groups = [f"  {group}={'|'.join(choices(group, argv))}" for group in GROUPS]
    return "\n".join([
        "usage: hersd-train [KEY=VALUE ...] [--dry-run]", "",
        "Runs one DDPG+HER training run and prints the path of its MCAP log; re-running the same",
        "command resumes an interrupted run from its last checkpoint. Defaults are the seed paper's",
        "appendix settings. --dry-run makes the same checks, then prints the resolved run (its folder",
        "and state, its identity, every setting) and trains nothing. See docs/ARCHITECTURE.md.", "",
        "config groups (conf/<group>/*.yaml):", *groups, "",
        "keys (key=default  meaning; a group's keys also take values after its choice, e.g. schedule.beta1=0.5):",
        *schema_lines(TrainConfig), "",
        *update_path_lines(), "",
        "schedules (eps(k): the relabel rate of epoch k = 1..K; schedule=<kind> or schedule.kind=<kind>, then its settings):",
        *schedule_lines(chosen_schedules(argv)),
        *learner_lines(argv),
    ])


def dry_run_lines(spec: RunSpec) -> list[str]:
    """``--dry-run``: the resolved run: its folder and state as a sweep's dry run lists it (:func:`run_status`, e.g.
    ``failed: <its error's first line>, epoch 1 of 3``), its identity (the hash of :func:`run_identity`) and every
    setting as ``key=value``, nested ones flattened with dots."""
    from hersd.contract.config import config_record
    from hersd.contract.runstore import run_status

    status = run_status(spec.folder, spec.config.epochs)
    state = f"{status.state}: {status.detail}" if status.detail else status.state
    lines = [f"run: {spec.folder} ({state})", f"identity: {spec.run_id}", "settings:"]
    pending = list(config_record(spec.config).items())
    while pending:
        key, value = pending.pop(0)
        if isinstance(value, dict):
            pending[:0] = [(f"{key}.{name}", item) for name, item in value.items()]
        else:
            shown = "null" if value is None else str(value).lower() if isinstance(value, bool) else value
            lines.append(f"  {key}={shown}")
    return lines


def _fail(message: str, code: int = 2) -> None:
    print(f"hersd-train: error: {message}", file=sys.stderr)
    sys.exit(code)


def checked_run(argv: list[str], writes: bool = True) -> RunSpec:
    """The resolved run of a command line (:func:`hersd.contract.runspec.resolve`), its folders checked (created,
    writable, no file where the run's folder goes; ``writes`` False, a dry run: the folders created to check are
    removed again) and this machine (:func:`check_machine`: its device and precision); bad input ends the command
    with one line and exit code 2."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from hersd.contract.compose import compose_train, explain_config_error
    from hersd.contract.runspec import resolve
    from hersd.contract.runstore import check_run_path, check_writable
    from hersd.engine.resources import check_machine  # torch loads only for a device or precision that needs it

    try:
        spec = resolve(compose_train(argv))
        if spec.config.run_dir is None:
            check_writable(Path(spec.config.results_dir), keep=writes)
            check_run_path(spec.folder, Path(spec.config.results_dir))
        else:
            check_writable(spec.folder, "run_dir", keep=writes)
        check_machine(*spec.machine)
    except ConfigError as err:
        _fail(str(err))
    except (HydraException, OmegaConfBaseException) as err:
        _fail(explain_config_error(err))
    return spec


def unknown_option(argv: list[str], command: str, options: tuple[str, ...]) -> str | None:
    """The one-line error for the first option (``-...``) of a command line that ``command`` does not take (its
    ``options``; the rest of its command line is KEY=VALUE overrides), None when there is none."""
    unknown = [arg for arg in argv if arg.startswith("-") and arg not in options]
    return (f"unknown option {unknown[0]}; {command} takes {', '.join(options)} and KEY=VALUE overrides "
            f"({command} --help lists them)") if unknown else None


@sigterm_as_ctrl_c()  # ``kill PID`` too: one line, exit 130, the finished epochs kept
def main(argv: list[str] | None = None) -> None:
    """Entry point of ``hersd-train``; bad input and a full disk end with one line on stderr and exit code 2,
    a run whose losses turn NaN or infinite, or whose schedule's rate raises, with one line and exit code 1, an interrupt (Ctrl-C) with one line
    and exit code 130: in training, naming the folder that keeps the finished epochs; before it (the config
    composed, torch and MuJoCo loaded), saying so."""
    argv = sys.argv[1:] if argv is None else argv
    try:
        if any(arg in HELP_FLAGS for arg in argv):
            try:
                print(usage(argv))
            except ConfigError as err:
                _fail(str(err))
            return
        if said := unknown_option(argv, "hersd-train", (*HELP_FLAGS, DRY_RUN_FLAG)):
            _fail(said)
        dry_run = DRY_RUN_FLAG in argv
        argv = [arg for arg in argv if arg != DRY_RUN_FLAG]
        spec = checked_run(argv, writes=not dry_run)
        if dry_run:
            signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # a listing: a reader gone (``| head``) ends it quietly
            print("\n".join(dry_run_lines(spec)))
            return
        from hersd.contract.runstore import RunLockedError
        from hersd.contract.schedules import ScheduleRateRaised
        from hersd.engine.train import NonFiniteLossError, RunStateError, train  # torch and MuJoCo: the input valid
    except KeyboardInterrupt:
        print("hersd-train: interrupted before training began; re-run the same command to start", file=sys.stderr)
        sys.exit(130)
    try:
        log_path = train(spec, command=" ".join(["hersd-train", *argv]))
    except ConfigError as err:
        _fail(str(err))
    except RunLockedError as err:
        _fail(f"{err}; wait for it to finish")
    except (RunStateError, DiskFullError) as err:
        _fail(str(err))
    except NonFiniteLossError as err:
        _fail(str(err), code=1)
    except ScheduleRateRaised as err:
        _fail(f"{err}; the finished epochs are kept in {spec.folder}", code=1)
    except KeyboardInterrupt:
        print(f"hersd-train: interrupted; the finished epochs are kept in {spec.folder}: re-run the same "
              "command to resume", file=sys.stderr)
        sys.exit(130)
    print(log_path)


if __name__ == "__main__":
    main()


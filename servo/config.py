"""Run configuration: TOML, every field documented with its unit, a complete default.

The default (no file) is the simulated HDD drive of docs/model.md section 5 at 50 kHz, the
paper's compensator with the drive's nominal parameters, and the ``servo run`` scenario.
A file needs only the fields it changes::

    [drive]
    sigma = 400.0          # A/m

    [run]
    duration_s = 1.0

Unknown sections or keys, wrong types and out-of-range values raise
:class:`~servo.errors.ConfigError` naming the key (``drive.sigma``).  ``servo config``
prints the full default with the documentation of every field; ``docs/config.md`` is the
same text as a table.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import textwrap
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servo import physics
from servo.errors import ConfigError, first_line
from servo.fields import P, check_value, choices_of, documented, range_text


@dataclass
class RunConfig:
    """How the run is stepped and recorded."""

    sample_rate_hz: float = P(50_000.0, "Hz", "servo sample rate (one tick per sample)", 100.0, 1e6)
    duration_s: float = P(0.6, "s", "length of the run", 0.0, 3600.0, lo_open=True)
    seed: int = P(1, "-", "seed of the simulated sensor noise (same seed, same bits)", 0, 2**63 - 1)
    excitation_every: int = P(1, "ticks", "excitation/reference task period", 1, 10**6)
    estimator_every: int = P(10, "ticks", "tracking-error estimator task period", 1, 10**6)
    log_every: int = P(1, "ticks", "logging period (decimation of the run log)", 1, 10**6)
    fast_path: bool = P(False, "-", "run the all-compiled loop instead of tick by tick")
    fault_position: float = P(0.0, "m", "a run whose position leaves +-this stops as unstable, exit 3 "
                              "(0: 95 % of drive.stroke, short of the hard stops; docs/runtime.md)", 0.0)
    fault_limit_share: float = P(0.5, "-", "a run whose current command sits at its limit on more than this share "
                                 "of the ticks of any fault_window_s window stops as unstable, exit 3 (1: never)",
                                 0.0, 1.0, lo_open=True)
    fault_window_s: float = P(0.05, "s", "the window of fault_limit_share", 0.0, 60.0, lo_open=True)


def _type_name(f: dataclasses.Field) -> str:
    """The annotation of a :func:`P` field, from its default: ``bool``, ``int``, ``float``, ``list``."""
    v = f.default_factory() if f.default is dataclasses.MISSING else f.default
    return "bool" if isinstance(v, bool) else type(v).__name__


def _gathered(name: str, doc: str, own_head: list, effects: list, own_tail: list) -> type:
    """A section dataclass of the section's own fields around the fields every physical
    effect declares for it (:mod:`servo.physics`)."""
    items = [*own_head, *effects, *own_tail]
    cls = dataclasses.make_dataclass(name, [(k, _type_name(f), f) for k, f in items], namespace={"__doc__": doc})
    cls.__module__ = __name__
    return cls


DriveConfig = _gathered(
    "DriveConfig",
    """The simulated VCM drive (docs/model.md section 5).  Forces are in amperes of VCM current
    (force constant 1 N/A at the stroke centre), positions in metres at the head.  Each
    physical effect's fields are declared by its module in ``servo/physics/``.""",
    [],
    physics.drive_fields(),
    [
        ("substeps", P(2, "-", "RK4 sub-steps per constant-input interval", 1, 1000)),
        ("initial_position", P(0.0, "m", "where the arm is held when the run starts")),
    ],
)


@dataclass
class LinkConfig:
    """The command path between controller and drive."""

    loop: str = P("host", "-", "where the loop closes: 'host' (the host's controller, its commands over the link) or "
                  "'board' (the board runs the controller kind; the host sends references and gain changes and "
                  "records the board's log; no link latency in the loop; docs/firmware.md)", choices=("host", "board"))
    command_latency_ticks: int = P(0, "ticks", "a command computed at tick k is applied at k+d (the host's loop; a "
                                   "loop on the board has none)", 0, 1000)
    batch: int = P(1, "samples", "serial link: samples per frame (and commands per reply); needs d >= batch - 1, "
                   "and d >= batch on a real-time board", 1, 32)
    timeout_s: float = P(0.2, "s", "serial link: the host stops when no frame has come from the board for this long",
                         0.0, 60.0, lo_open=True)
    watchdog_s: float = P(0.05, "s", "serial link: the board falls to zero current when no command has come for "
                          "this long (a lockstep board: at least the link's round trip + 0.5 s)", 1e-6, 60.0)
    ready_timeout_s: float = P(2.0, "s", "serial link: the board falls to zero current when the host has not "
                               "started the run (nor said anything) this long after READY", 1e-3, 60.0)
    late_limit_ticks: int = P(0, "ticks", "serial link, real-time board: consecutive ticks it may hold the previous "
                              "current when a command is late; one more is a fault", 0, 65535)
    baudrate: int = P(921600, "bit/s", "serial link: line rate of a real UART (pty, socket:// and USB CDC ignore it)",
                      50, 100_000_000)

    @property
    def loop_latency_ticks(self) -> int:
        """Ticks from a command to the drive inside the loop: ``command_latency_ticks``
        when the host closes the loop, 0 when the board does (``loop = "board"``: the
        command never crosses the link).  The one place that decides it: the simulated
        drive, the drivers' info and the design code (``servo.lti``,
        ``servo.loop.design``, ``servo.experiments``) read it."""
        return self.command_latency_ticks if self.loop == "host" else 0


def _kind_names() -> tuple[str, ...]:
    from servo.controllers import kind_names  # imported when first needed: the kinds load kernels

    return kind_names()


def _scenario_kind_names() -> tuple[str, ...]:
    from servo.scenarios import kind_names  # imported when first needed: the kinds load scipy

    return kind_names()


def _kind_sections() -> dict:
    from servo.controllers import KINDS

    return {name: kind.Section() for name, kind in KINDS.items()}


@dataclass
class ControllerConfig:
    """Which controller runs, the command limit and the motion signals every controller and
    the compensator share.  Each kind's own parameters are in its section
    ``[controller.<kind>]`` (docs/controllers.md)."""

    kind: str = P("pi", "-", "the controller that runs (a registered kind, docs/controllers.md)", choices=_kind_names)
    current_limit: float = P(1.0, "A", "total command limit", 0.0, None, lo_open=True)
    velocity_source: str = P("auto", "-", "'auto': measured if the drive has it, else estimated", choices=("auto", "estimated"))
    velocity_cutoff_hz: float = P(2000.0, "Hz", "cutoff of the velocity estimator", 0.0, None, lo_open=True)
    direction_deadband: float = P(5e-6, "m/s", "speed needed to declare a direction change", 0.0)
    kinds: dict = field(default_factory=_kind_sections, repr=False)  # kind name -> its section

    def __getattr__(self, name: str):
        """``cfg.controller.pi``: the section of kind ``pi``."""
        kinds = self.__dict__.get("kinds")
        if kinds is not None and name in kinds:
            return kinds[name]
        raise AttributeError(f"'ControllerConfig' has no attribute or kind section {name!r}")

    @property
    def section(self):
        """The section of the kind that runs."""
        return self.kinds[self.kind]


CompensatorConfig = _gathered(
    "CompensatorConfig",
    """The paper's compensator, eq. (8-9), and the terms beyond it; defaults are the default
    drive's exact values.  Each term's fields are declared by its effect's module in
    ``servo/physics/``.""",
    [
        ("enabled", P(True, "-", "add the compensation current u_c (false: servo run and servo loop run without it, "
                      "and refuse --compensation on)")),
    ],
    physics.compensator_fields(),
    [
        ("fast_on_speed", P(2e-3, "m/s", "SLOW->FAST needs at least this speed", 0.0)),
        ("fast_off_speed", P(1e-3, "m/s", "FAST->SLOW below this speed", 0.0)),
        ("fast_on_distance", P(1.25e-5, "m", "SLOW->FAST needs this distance since the turnaround", 0.0)),
        ("authority", P(0.0, "A", "the largest |u_c| the compensator may command, whatever its model (0: unbounded, "
                        "eq. 9 as the paper writes it; docs/compensate.md)", 0.0)),
    ],
)  # fmt: skip


@dataclass
class ScenarioConfig:
    """The ``servo run`` scenario: hold, reference steps, a sinusoidal force disturbance,
    and an optional excitation current for frequency-response measurements; or the HDD
    benchmark's track following (docs/hdd.md)."""

    kind: str = P("steps", "-", "steps: the fields below; hdd_benchmark: follow a track with the NSS HDD "
                  "benchmark's runout, force disturbance and noise, reported as PES figures (docs/hdd.md)",
                  choices=_scenario_kind_names)  # fmt: skip
    hdd_version: int = P(2, "-", "hdd_benchmark: the benchmark's version (1 or 2); its nominal plant is the drive "
                         "where [drive] sets nothing (docs/hdd.md)", 1, 2)  # fmt: skip
    hdd_package: str = P("", "-", "hdd_benchmark: folder of your copy of the NSS HDD benchmark package (relative to "
                         "the working directory); its RROSequence.mat, the written-in runout, is added to the RRO. "
                         "Empty: the RRO is the three harmonics alone")  # fmt: skip

    step_times: list = P([0.05, 0.12, 0.19, 0.28], "s", "times of the reference steps", 0.0)
    step_positions: list = P([0.3e-6, 0.0, 20e-6, 0.0], "m", "reference after each step, from the holding position", -0.015, 0.015)
    disturbance_amplitude: float = P(1e-3, "A", "sinusoidal disturbance force amplitude", 0.0)
    disturbance_hz: float = P(40.0, "Hz", "its frequency", 0.0)
    disturbance_start: float = P(0.37, "s", "when it starts", 0.0)
    excitation: str = P("none", "-", "excitation current added to the controller's output (for servo frf): none, "
                        "chirp (log sweep f_min to f_max over the rest of the run), multisine (Schroeder phases, "
                        "lines 1/period apart in [f_min, f_max]) or prbs (flat to about f_max)",
                        choices=("none", "chirp", "multisine", "prbs"))  # fmt: skip
    excitation_amplitude: float = P(0.5e-3, "A", "its peak", 0.0)
    excitation_f_min: float = P(10.0, "Hz", "lowest frequency (chirp start; multisine band)", 0.0, lo_open=True)
    excitation_f_max: float = P(2000.0, "Hz", "highest frequency (chirp end; multisine band; prbs bit rate ~ f_max/0.44)",
                                0.0, lo_open=True)  # fmt: skip
    excitation_period: float = P(0.1, "s", "multisine and prbs period (their lines are 1/period apart)", 0.0, 10.0, lo_open=True)
    excitation_start: float = P(0.0, "s", "when it starts; it runs to the end of the run", 0.0)


SECTIONS = {
    "run": RunConfig,
    "drive": DriveConfig,
    "link": LinkConfig,
    "controller": ControllerConfig,
    "compensator": CompensatorConfig,
    "scenario": ScenarioConfig,
}


@dataclass
class Config:
    """The whole configuration; ``Config()`` is the complete default."""

    run: RunConfig = field(default_factory=RunConfig)
    drive: DriveConfig = field(default_factory=DriveConfig)
    link: LinkConfig = field(default_factory=LinkConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    compensator: CompensatorConfig = field(default_factory=CompensatorConfig)
    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)

    @property
    def dt(self) -> float:
        """Sample period, s."""
        return 1.0 / self.run.sample_rate_hz

    @property
    def n_ticks(self) -> int:
        """Ticks in the run."""
        return max(1, int(round(self.run.duration_s * self.run.sample_rate_hz)))

    def replace(self, **sections: dict) -> "Config":
        """A copy with some fields changed: ``cfg.replace(run={"duration_s": 1.0})``."""
        data = to_dict(self)
        if self.drive == _default_drive(self.scenario):  # a drive left at its default follows the scenario
            data["drive"] = {}
        for name, values in sections.items():
            into = data.setdefault(name, {})
            for k, v in values.items():  # a kind's section is updated, not replaced
                if isinstance(v, dict) and isinstance(into.get(k), dict):
                    into[k] = {**into[k], **v}
                else:
                    into[k] = v
        return from_dict(data)


# ---------------------------------------------------------------------------- loading


def _unknown(kind: str, name: str, known) -> ConfigError:
    close = difflib.get_close_matches(name.split(".")[-1], list(known), n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    return ConfigError(f"config: unknown {kind} '{name}'{hint}")


def from_dict(data: dict) -> Config:
    """Build and validate a :class:`Config` from nested dicts (the TOML document)."""
    if not isinstance(data, dict):
        raise ConfigError("config: the document must be a table of sections")
    sections = {}
    for name, values in data.items():
        if name not in SECTIONS:
            raise _unknown("section", name, SECTIONS)
        if not isinstance(values, dict):
            raise ConfigError(f"config: [{name}] must be a table")
        if name == "controller":
            sections[name] = _controller_section(values)
        else:
            sections[name] = _section(name, SECTIONS[name], values)
    defaults = _drive_defaults(sections.get("scenario") or ScenarioConfig())
    if defaults:  # the scenario's drive (the HDD benchmark's plant of its version), then the document's [drive]
        sections["drive"] = _section("drive", DriveConfig, {**defaults, **data.get("drive", {})})
    cfg = Config(**sections)
    _check_consistency(cfg)
    return cfg


def _drive_defaults(scenario: "ScenarioConfig") -> dict:
    """The ``[drive]`` values the scenario kind stands for (``ScenarioKind.drive_defaults``)."""
    from servo.scenarios import KINDS

    return KINDS[scenario.kind].drive_defaults(scenario)


def _default_drive(scenario: "ScenarioConfig") -> "DriveConfig":
    """The drive a config with this scenario and no ``[drive]`` values has."""
    return _section("drive", DriveConfig, _drive_defaults(scenario))


def _section(key: str, cls: type, values: dict, extra=()):
    """An instance of section ``cls`` from its TOML table ``values``, validated."""
    by_name = {f.name: f for f in documented(cls)}
    kwargs = {}
    renamed = physics.renamed_keys()
    for k, value in values.items():
        if k not in by_name:
            if f"{key}.{k}" in renamed:
                raise ConfigError(f"config: {key}.{k} was renamed: write {key}.{renamed[f'{key}.{k}']} "
                                  "(docs/config.md)")  # fmt: skip
            raise _unknown("key", f"{key}.{k}", [*by_name, *extra])
        kwargs[k] = check_value(f"{key}.{k}", value, by_name[k])
    return cls(**kwargs)


def _controller_section(values: dict) -> "ControllerConfig":
    """``[controller]``: its own keys, and one sub-table ``[controller.<kind>]`` per kind."""
    from servo.controllers import KINDS

    own = {k: v for k, v in values.items() if not isinstance(v, dict)}
    for k in own:
        homes = [n for n, kind in KINDS.items() if k in {f.name for f in documented(kind.Section)}]
        if k not in {f.name for f in documented(ControllerConfig)} and homes:
            raise ConfigError(f"config: controller.{k} belongs to the controller kind's section: "
                              f"write it under [controller.{homes[0]}]")  # fmt: skip
    c = _section("controller", ControllerConfig, own, extra=KINDS)
    for k, v in values.items():
        if isinstance(v, dict):
            if k not in KINDS:
                err = _unknown("controller kind section", f"controller.{k}", KINDS)
                raise ConfigError(f"{err} (a kind from a plugin? load it with --plugin MODULE)")
            c.kinds[k] = _section(f"controller.{k}", KINDS[k].Section, v)
    return c


def _check_consistency(cfg: Config) -> None:
    d, c, s = cfg.drive, cfg.compensator, cfg.scenario
    if d.Fs < d.Fc:
        raise ConfigError(f"config: drive.Fs = {d.Fs!r} must be >= drive.Fc = {d.Fc!r} (breakaway >= sliding)")
    if not (len(d.mode_hz) == len(d.mode_zeta) == len(d.mode_gain)):
        raise ConfigError("config: drive.mode_hz, drive.mode_zeta and drive.mode_gain must have the same length")
    nyquist = cfg.run.sample_rate_hz / 2
    for i, f in enumerate(d.mode_hz):
        if f >= nyquist:
            raise ConfigError(f"config: drive.mode_hz[{i}] = {f!r} is at or above Nyquist ({nyquist:g} Hz)")
    if len(c.periodic_amplitudes) != len(c.periodic_phases) or len(c.periodic_amplitudes) > 4:
        raise ConfigError("config: compensator.periodic_amplitudes and periodic_phases must have the same length, at most 4")
    if 0 < c.coulomb_static < c.coulomb_extra:
        raise ConfigError("config: compensator.coulomb_static must be 0 (no Stribeck rise) or >= compensator.coulomb_extra")
    if c.fast_off_speed > c.fast_on_speed:
        raise ConfigError("config: compensator.fast_off_speed must be <= compensator.fast_on_speed (switch hysteresis)")
    if len(s.step_times) != len(s.step_positions):
        raise ConfigError("config: scenario.step_times and scenario.step_positions must have the same length")
    if any(b < a for a, b in zip(s.step_times, s.step_times[1:])):
        raise ConfigError("config: scenario.step_times must be increasing")
    if cfg.link.command_latency_ticks < cfg.link.batch - 1:
        raise ConfigError("config: link.command_latency_ticks must be >= link.batch - 1 (a frame's last sample "
                          "needs the commands of the frame before)")
    link = cfg.link
    if link.late_limit_ticks * 1e6 > max(1, round(link.watchdog_s * 1e6)) * cfg.run.sample_rate_hz:
        raise ConfigError(f"config: link.late_limit_ticks = {link.late_limit_ticks} ticks "
                          f"({link.late_limit_ticks / cfg.run.sample_rate_hz:g} s) must not be longer than "
                          f"link.watchdog_s = {link.watchdog_s:g} s: a board refuses a late limit beyond its watchdog")  # fmt: skip
    if abs(d.initial_position) >= d.stroke:
        raise ConfigError("config: drive.initial_position must lie inside +-drive.stroke")
    if cfg.run.fault_position >= d.stroke:  # the arm meets its hard stops at +-stroke first
        raise ConfigError(f"config: run.fault_position = {cfg.run.fault_position:g} m is not inside drive.stroke = "
                          f"{d.stroke:g} m: the arm meets its hard stops first and the check never fires "
                          "(0: 95 % of the stroke)")  # fmt: skip
    _check_physics(cfg)
    from servo.controllers import KINDS

    KINDS[cfg.controller.kind].check(cfg.controller.section, cfg)  # only the kind that runs


def _check_physics(cfg: Config) -> None:
    """Values each within its range whose combination makes a run's result meaningless:
    refused with the reason (docs/config.md, "Checks across fields")."""
    d, s = cfg.drive, cfg.scenario
    nyquist = cfg.run.sample_rate_hz / 2
    if d.position_quantum >= d.stroke:
        raise ConfigError(f"config: drive.position_quantum = {d.position_quantum:g} m is not below drive.stroke = "
                          f"{d.stroke:g} m: every measured position would be one of a few levels")  # fmt: skip
    if 0 < d.position_quantum < d.stroke * 2.0**-52:  # 5e-324 made every measured position infinite (exit 3)
        raise ConfigError(f"config: drive.position_quantum = {d.position_quantum:g} m is finer than a double resolves "
                          f"across drive.stroke = {d.stroke:g} m ({d.stroke * 2.0**-52:.3g} m): write 0 for no "
                          "quantisation")  # fmt: skip
    stiffness = abs(d.K) + d.sigma  # the rigid body's spring at a turnaround: bias plus pre-sliding
    f_n = math.sqrt(stiffness / d.J) / (2 * math.pi)
    if f_n >= nyquist:
        raise ConfigError(f"config: drive.J = {d.J:g} A*s^2/m with drive.K = {d.K:g} and drive.sigma = {d.sigma:g} A/m "
                          f"puts the arm's natural frequency at {f_n:.3g} Hz, at or above Nyquist ({nyquist:g} Hz): "
                          "no run at run.sample_rate_hz can resolve it")  # fmt: skip
    if s.kind == "steps" and s.disturbance_amplitude > 0 and s.disturbance_hz >= nyquist:
        raise ConfigError(f"config: scenario.disturbance_hz = {s.disturbance_hz:g} is at or above Nyquist ({nyquist:g} Hz): "
                          "sampled at this rate it vanishes or aliases")  # fmt: skip
    if s.kind != "steps" or s.excitation == "none":
        return
    used = ("excitation_f_max",) if s.excitation == "prbs" else ("excitation_f_min", "excitation_f_max")
    for key in used:
        f = getattr(s, key)
        if f >= nyquist:
            raise ConfigError(f"config: scenario.{key} = {f:g} is at or above Nyquist ({nyquist:g} Hz) for a "
                              f"{s.excitation} excitation")  # fmt: skip
    if s.excitation == "multisine" and s.excitation_f_min > s.excitation_f_max:
        raise ConfigError(f"config: scenario.excitation_f_min = {s.excitation_f_min:g} is above excitation_f_max = "
                          f"{s.excitation_f_max:g} Hz")  # fmt: skip
    if s.excitation != "prbs":
        return
    from servo.scenarios.excitation import PRBS_BIT_HZ  # imported when first needed: the kinds load scipy

    if PRBS_BIT_HZ / s.excitation_f_max > s.excitation_period:
        raise ConfigError(f"config: scenario.excitation_f_max = {s.excitation_f_max:g} Hz: a prbs flat to it holds each "
                          f"bit {PRBS_BIT_HZ / s.excitation_f_max:.3g} s, longer than scenario.excitation_period = "
                          f"{s.excitation_period:g} s; raise it to at least {PRBS_BIT_HZ / s.excitation_period:.3g} Hz")  # fmt: skip


def load_config(path: str | Path | None = None) -> Config:
    """The default config, or the default updated by the TOML file at ``path``."""
    if path is None:
        return Config()
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"config: no such file: {p}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"config: cannot read {p}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, ValueError) as exc:  # ValueError: an integer of more digits than Python reads
        raise ConfigError(f"config: {p} is not valid TOML: {first_line(exc)}") from None
    return from_dict(data)


def to_dict(cfg: Config) -> dict:
    """Nested dicts of every field (a complete, loadable document)."""
    out = {}
    for name in SECTIONS:
        section = getattr(cfg, name)
        out[name] = {f.name: _plain(getattr(section, f.name)) for f in documented(type(section))}
    for kind, section in cfg.controller.kinds.items():
        out["controller"][kind] = dataclasses.asdict(section)
    return out


def _plain(v: Any) -> Any:
    return list(v) if isinstance(v, list) else v


# ------------------------------------------------------------------------ documenting


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def to_toml(cfg: Config | None = None, comments: bool = True) -> str:
    """The config as a TOML document, each field preceded by its doc, unit and range."""
    cfg = cfg or Config()
    out = []
    for name, section in _all_sections(cfg):
        cls = type(section)
        if comments:  # the docstring's first paragraph, whole
            out += [f"# {line}" for line in textwrap.wrap(section_doc(cls), 86)]
        out.append(f"[{name}]")
        for f in documented(cls):
            m = f.metadata
            if comments:
                rng = f"one of {', '.join(choices_of(m))}" if m["choices"] else range_text(m, f.type != "bool")
                out.append(f"# {m['doc']} [{m['unit']}] ({rng})")
            out.append(f"{f.name} = {_toml_value(getattr(section, f.name))}")
        out.append("")
    return "\n".join(out)


def section_doc(cls) -> str:
    """The first paragraph of a section's docstring, on one line."""
    return " ".join(cls.__doc__.strip().split("\n\n")[0].split())


def _all_sections(cfg: Config):
    """``(toml name, section)`` of every section, each controller kind's after [controller]."""
    for name in SECTIONS:
        yield name, getattr(cfg, name)
        if name == "controller":
            for kind, section in cfg.controller.kinds.items():
                yield f"controller.{kind}", section


def to_markdown() -> str:
    """Reference of every field as Markdown tables (``docs/config.md``)."""
    out = [
        "# Configuration reference",
        "",
        "Generated by `servo config --markdown` from `servo/config.py` and the effect modules of",
        "`servo/physics/` (each declares its own `[drive]` and `[compensator]` fields); every",
        "field, its default, unit and valid range.  A TOML file given with `--config` needs only",
        "the fields it changes; unknown keys and out-of-range values are errors naming the key.",
        "Values each in range are also refused together when they make a result meaningless",
        "(a quantum not below the stroke, a frequency at or above Nyquist, a natural frequency",
        "the sample rate cannot resolve, a PRBS bit longer than its period): docs/robustness.md.",
        "",
    ]
    for name, default in _all_sections(Config()):
        cls = type(default)
        out += [f"## [{name}]", "", cls.__doc__.strip().replace("\n    ", " "), ""]
        out += ["| key | default | unit | range | meaning |", "|---|---|---|---|---|"]
        for f in documented(cls):
            m = f.metadata
            free = f.type in ("str", str) and not m["choices"]
            rng = " / ".join(choices_of(m)) if m["choices"] else "a path" if free else range_text(m, f.type != "bool")
            out.append(
                f"| `{f.name}` | `{_toml_value(getattr(default, f.name))}` | {m['unit']} | {rng} | {m['doc']} |"
            )
        out.append("")
    out += ["## Renamed keys", "", "A config that uses a former name is refused with one line naming the new one.", "",
            "| former key | now |", "|---|---|"]  # fmt: skip
    for old, new in physics.renamed_keys().items():
        out.append(f"| `{old}` | `{old.split('.')[0]}.{new}` |")
    out.append("")
    return "\n".join(out)

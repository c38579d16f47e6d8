"""What a monitored machine is: its model, its measurement set-up, its components and the alarm rules.

A :class:`MonitorConfig` is the plain-data description that ``cappe monitor init`` stores for a machine id. The
monitored quantities are the stiffness factors of *components*: groups of model stiffness parameters that fail
together (the three directions of the front bearing, the three of one housing screw). A component's factor
multiplies every parameter of its group; 1 is the reference (healthy) model, 0.9 a 10 % loss. Single stiffness
parameters of a 17-parameter spindle are not all identifiable from a few sensors, component factors are, and
they are what a maintenance decision is about (which part to re-tighten or replace).

:func:`default_config` derives the components from a model's elements: elements whose names differ only by a
direction suffix (``front_x``, ``front_y``, ``front_z``) form one component, every other element with stiffness
parameters is a component of its own (``screw1``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cappe.exceptions import DataError
from cappe.model import NumericModel, Structure

__all__ = ["CONFIG_FORMAT", "EXCITATIONS", "SEVERITY_GRADES", "SSI_STABILITY", "Component", "MonitorConfig",
           "SeverityThresholds", "default_components", "default_config", "severity_rank", "worst_severity"]

CONFIG_FORMAT = "cappe.monitor-config/1"

#: How a machine's measurements are excited: a measured force (FRFs), or the unmeasured process (output-only).
EXCITATIONS = ("measured", "operational")

#: Stabilization criteria of output-only modal analysis that a machine's config may set: the keyword arguments of
#: :func:`cappe.identify.ssi_cov` (its defaults apply to those not set) and the range of each.
SSI_STABILITY = {"freq_tol": (0.0, 0.5), "damping_tol": (0.0, 10.0), "mac_tol": (0.0, 1.0),
                 "min_fraction": (0.0, 1.0), "max_damping": (0.0, 1.0)}

#: The thesis's three grades (1.1, block 6), from harmless to stop-the-machine.
SEVERITY_GRADES = ("tolerable", "conditionally tolerable", "intolerable")

def severity_rank(grade: str | None) -> int:
    """0 for no grade, 1, 2, 3 from tolerable to intolerable; a grade cappe does not know (a store written by
    other software) ranks as the worst, so that it is never hidden.

    Parameters
    ----------
    grade : str or None
        A grade of :data:`SEVERITY_GRADES`, another text, or None.

    Returns
    -------
    int

    Examples
    --------
    >>> [severity_rank(g) for g in (None, "tolerable", "intolerable", "on fire")]
    [0, 1, 3, 4]
    """
    if grade is None:
        return 0
    return SEVERITY_GRADES.index(grade) + 1 if grade in SEVERITY_GRADES else len(SEVERITY_GRADES) + 1


def worst_severity(grades: Sequence[str]) -> str | None:
    """The most severe of ``grades`` (None for none).

    Parameters
    ----------
    grades : sequence of str
        Severity grades (:func:`severity_rank` orders them).

    Returns
    -------
    str or None
    """
    return max(grades, key=severity_rank) if grades else None


_DIRECTION_SUFFIX = re.compile(r"_(x|y|z|rx|ry|rz|radial|axial)$")


@dataclass(frozen=True)
class Component:
    """A group of stiffness parameters that change together, e.g. one bearing or one screw.

    Attributes
    ----------
    name : str
        Identifier (``front``, ``screw1``), used in the history store and on the command line.
    label : str
        Words for reports (``front bearing``).
    parameters : tuple of str
        Model parameters scaled by the component's factor.
    """

    name: str
    label: str
    parameters: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "label": self.label, "parameters": list(self.parameters)}


@dataclass(frozen=True)
class SeverityThresholds:
    """Grades of a relative change: below ``tolerable`` it is tolerable, above ``intolerable`` it is intolerable,
    in between conditionally tolerable (the operation has to change, thesis 1.1).

    Both are fractions of the healthy value (0.05 = 5 %) and apply to the magnitude of the diagnosed change.

    Attributes
    ----------
    tolerable : float
        Relative change below which a fault is tolerable (0.05 = 5 %).
    intolerable : float
        Relative change from which it is intolerable (> ``tolerable``).
    """

    tolerable: float = 0.05
    intolerable: float = 0.25

    def __post_init__(self) -> None:
        if not (0 < self.tolerable < self.intolerable):
            msg = (f"severity thresholds must satisfy 0 < tolerable < intolerable; got tolerable "
                   f"{self.tolerable!r}, intolerable {self.intolerable!r}")
            raise DataError(msg)

    def grade(self, change: float) -> str:
        """The grade of a relative change (sign ignored).

        Parameters
        ----------
        change : float
            Relative change of the healthy value (0.1 = 10 %).

        Returns
        -------
        str
            One of :data:`SEVERITY_GRADES`.

        Examples
        --------
        >>> SeverityThresholds().grade(-0.1)
        'conditionally tolerable'
        """
        size = abs(float(change))
        if size < self.tolerable:
            return SEVERITY_GRADES[0]
        return SEVERITY_GRADES[1] if size < self.intolerable else SEVERITY_GRADES[2]

    def to_dict(self) -> dict[str, float]:
        return {"tolerable": self.tolerable, "intolerable": self.intolerable}


@dataclass(frozen=True)
class MonitorConfig:
    """Everything the monitoring chain needs to know about one machine.

    Attributes
    ----------
    machine : str
        Machine id in the history store.
    model : str
        Model source (``builtin:NAME`` or a YAML path).
    params : mapping
        Parameter overrides that make the model the machine's healthy reference.
    position : mapping
        Axis position of the measurements.
    inputs, outputs : tuple of str
        The measured FRF channels (model input and output names).
    band : (float, float)
        Frequency band of the analysis in Hz.
    components : tuple of Component
        The monitored stiffness groups.
    fault_parameters : tuple of str
        Model parameters whose change is a diagnosis of its own (``preload``: both bearings together, by the
        bearing model's law).
    detection : {"cusum", "ewma"}
        Sequential test on the standardized component factors.
    false_alarm_rate : float
        Expected false alarms per healthy measurement, all charts together (0.001: one in 1000).
    shift : float
        The change, in baseline standard deviations, the charts are tuned to detect fastest.
    ewma_lambda : float
        Smoothing constant of the EWMA chart.
    severity : SeverityThresholds
        Default grades.
    severity_overrides : mapping name -> SeverityThresholds
        Grades of particular components or fault parameters.
    noise_floor : float
        Weighting floor of the FRF fit, as a fraction of each output's RMS FRF level.
    max_order : int
        Highest LSCF order of the modal feature extraction.
    slow_every : int
        Run the slow path (all component parameters freed one by one) every this many measurements; 0: only
        with an alarm.
    excitation : {"measured", "operational"}
        ``"measured"``: measurements are FRFs, or time data with the force channels (a hammer or shaker test).
        ``"operational"``: time data of the outputs only, recorded in operation under the unmeasured process
        force (output-only modal analysis, SSI-COV; the inputs are then where that force acts).
    ssi_orders : (int, int, int) or None
        Model orders of the SSI-COV stabilization diagram of an operational machine: lowest, highest, step (None:
        4, 8, ... up to twice the monitored modes in the band plus room for noise poles).
    ssi_block_rows : int or None
        Block rows of the SSI-COV Toeplitz matrix; outputs x block rows bound the model order (None: a period of
        the band's lowest frequency and enough for the highest order). Given with automatic orders, the orders stop
        at what the block rows allow.
    ssi_stability : mapping name -> float
        Stabilization criteria of :data:`SSI_STABILITY` that differ from :func:`cappe.identify.ssi_cov`'s defaults.
    """

    machine: str
    model: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    band: tuple[float, float]
    components: tuple[Component, ...]
    params: Mapping[str, float] = field(default_factory=dict)
    position: Mapping[str, float] = field(default_factory=dict)
    fault_parameters: tuple[str, ...] = ()
    detection: str = "cusum"
    false_alarm_rate: float = 1e-3
    shift: float = 2.0
    ewma_lambda: float = 0.2
    severity: SeverityThresholds = field(default_factory=SeverityThresholds)
    severity_overrides: Mapping[str, SeverityThresholds] = field(default_factory=dict)
    noise_floor: float = 0.01
    max_order: int = 24
    slow_every: int = 0
    excitation: str = "measured"
    ssi_orders: tuple[int, int, int] | None = None
    ssi_block_rows: int | None = None
    ssi_stability: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.machine:
            msg = "monitor config: machine id must not be empty"
            raise DataError(msg)
        if self.excitation not in EXCITATIONS:
            msg = (f"monitor config '{self.machine}': excitation must be one of {list(EXCITATIONS)}; got "
                   f"{self.excitation!r}")
            raise DataError(msg)
        if self.detection not in ("cusum", "ewma"):
            msg = f"monitor config '{self.machine}': detection must be 'cusum' or 'ewma'; got {self.detection!r}"
            raise DataError(msg)
        checks = (("false_alarm_rate", self.false_alarm_rate, 0.0, 0.5), ("shift", self.shift, 0.0, 50.0),
                  ("ewma_lambda", self.ewma_lambda, 0.0, 1.0), ("noise_floor", self.noise_floor, 0.0, 1.0))
        for name, value, lo, hi in checks:
            if not (np.isfinite(value) and lo < value <= hi):
                msg = f"monitor config '{self.machine}': {name} must be in ({lo:g}, {hi:g}]; got {value!r}"
                raise DataError(msg)
        lo, hi = self.band
        if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
            msg = f"monitor config '{self.machine}': band must be 0 <= LO < HI Hz; got {self.band!r}"
            raise DataError(msg)
        if not self.inputs or not self.outputs:
            msg = f"monitor config '{self.machine}': inputs and outputs must not be empty"
            raise DataError(msg)
        if not self.components:
            msg = f"monitor config '{self.machine}': at least one component is needed"
            raise DataError(msg)
        seen: dict[str, str] = {}
        for comp in self.components:
            if not comp.parameters:
                msg = f"monitor config '{self.machine}': component '{comp.name}' has no parameters"
                raise DataError(msg)
            for p in comp.parameters:
                if p in seen:
                    msg = (f"monitor config '{self.machine}': parameter '{p}' is in components '{seen[p]}' and "
                           f"'{comp.name}'; each parameter belongs to one component")
                    raise DataError(msg)
                seen[p] = comp.name
        names = [c.name for c in self.components] + list(self.fault_parameters)
        if len(set(names)) != len(names):
            msg = f"monitor config '{self.machine}': component and fault-parameter names must be unique; got {names}"
            raise DataError(msg)
        if self.max_order < 2 or self.slow_every < 0:
            msg = (f"monitor config '{self.machine}': max_order must be >= 2 and slow_every >= 0; got "
                   f"{self.max_order}, {self.slow_every}")
            raise DataError(msg)
        self._check_ssi()

    def _check_ssi(self) -> None:
        """The SSI-COV settings: only for an operational machine, orders and block rows that fit together."""
        where = f"monitor config '{self.machine}'"
        if self.excitation != "operational" and (self.ssi_orders is not None or self.ssi_block_rows is not None
                                                 or self.ssi_stability):
            msg = f"{where}: SSI-COV settings apply to excitation 'operational' only; got {self.excitation!r}"
            raise DataError(msg)
        if self.ssi_orders is not None:
            lo, hi, step = self.ssi_orders
            if not (2 <= lo <= hi and step >= 1):
                msg = f"{where}: ssi_orders must be LOWEST >= 2, HIGHEST >= LOWEST, STEP >= 1; got {self.ssi_orders}"
                raise DataError(msg)
        if self.ssi_block_rows is not None:
            rows = self.ssi_block_rows
            if rows < 2:
                msg = f"{where}: ssi_block_rows must be >= 2; got {rows}"
                raise DataError(msg)
            if self.ssi_orders is not None and self.ssi_orders[1] > rows * len(self.outputs):
                msg = (f"{where}: ssi_block_rows {rows} x {len(self.outputs)} outputs allow model orders up to "
                       f"{rows * len(self.outputs)}; got ssi_orders up to {self.ssi_orders[1]}")
                raise DataError(msg)
        for name, value in self.ssi_stability.items():
            if name not in SSI_STABILITY:
                msg = f"{where}: unknown SSI-COV stabilization criterion {name!r}; known: {list(SSI_STABILITY)}"
                raise DataError(msg)
            low, high = SSI_STABILITY[name]
            if not (np.isfinite(value) and low < value <= high):
                msg = f"{where}: SSI-COV {name} must be in ({low:g}, {high:g}]; got {value!r}"
                raise DataError(msg)

    @property
    def component_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.components)

    def component(self, name: str) -> Component:
        """The component of that name.

        Parameters
        ----------
        name : str
            Component name.

        Returns
        -------
        Component

        Raises
        ------
        DataError
            The machine has no such component.
        """
        for comp in self.components:
            if comp.name == name:
                return comp
        msg = f"machine '{self.machine}' has no component '{name}'; components: {list(self.component_names)}"
        raise DataError(msg)

    def thresholds(self, name: str) -> SeverityThresholds:
        """Severity thresholds of a component or fault parameter.

        Parameters
        ----------
        name : str
            Component or fault-parameter name.

        Returns
        -------
        SeverityThresholds
            Its override, else the default.
        """
        return self.severity_overrides.get(name, self.severity)

    def check_model(self, model: NumericModel) -> None:
        """Every name in the config exists in the model.

        Parameters
        ----------
        model : NumericModel
            The compiled model of ``self.model``.

        Raises
        ------
        DataError
            An input, output, parameter or axis of the config is not in the model.
        """
        known = set(model.parameter_names)
        for what, names, pool in (
            ("input", self.inputs, set(model.input_names)),
            ("output", self.outputs, set(model.output_names)),
            ("parameter", [p for c in self.components for p in c.parameters] + list(self.fault_parameters)
             + list(self.params), known),
            ("axis", list(self.position), set(model.axis_names)),
        ):
            unknown = [n for n in names if n not in pool]
            if unknown:
                msg = (f"monitor config '{self.machine}': {what}(s) {unknown} not in model {self.model}; "
                       f"known: {sorted(pool)}")
                raise DataError(msg)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": CONFIG_FORMAT,
            "machine": self.machine,
            "model": self.model,
            "params": dict(self.params),
            "position": dict(self.position),
            "inputs": list(self.inputs),
            "outputs": list(self.outputs),
            "band": list(self.band),
            "components": [c.to_dict() for c in self.components],
            "fault_parameters": list(self.fault_parameters),
            "detection": self.detection,
            "false_alarm_rate": self.false_alarm_rate,
            "shift": self.shift,
            "ewma_lambda": self.ewma_lambda,
            "severity": self.severity.to_dict(),
            "severity_overrides": {k: v.to_dict() for k, v in self.severity_overrides.items()},
            "noise_floor": self.noise_floor,
            "max_order": self.max_order,
            "slow_every": self.slow_every,
            "excitation": self.excitation,
            "ssi_orders": None if self.ssi_orders is None else list(self.ssi_orders),
            "ssi_block_rows": self.ssi_block_rows,
            "ssi_stability": dict(self.ssi_stability),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MonitorConfig:
        """Read a config written by :meth:`to_dict`; a wrong format or a missing key is a `DataError`.

        Parameters
        ----------
        data : mapping
            A ``cappe.monitor-config/1`` document.

        Returns
        -------
        MonitorConfig
        """
        if data.get("format") != CONFIG_FORMAT:
            msg = f"monitor config format must be {CONFIG_FORMAT!r}; got {data.get('format')!r}"
            raise DataError(msg)
        try:
            severity = data.get("severity", {})
            return cls(
                machine=str(data["machine"]),
                model=str(data["model"]),
                params={str(k): float(v) for k, v in data.get("params", {}).items()},
                position={str(k): float(v) for k, v in data.get("position", {}).items()},
                inputs=tuple(data["inputs"]),
                outputs=tuple(data["outputs"]),
                band=(float(data["band"][0]), float(data["band"][1])),
                components=tuple(Component(str(c["name"]), str(c.get("label", c["name"])), tuple(c["parameters"]))
                                 for c in data["components"]),
                fault_parameters=tuple(data.get("fault_parameters", ())),
                detection=str(data.get("detection", "cusum")),
                false_alarm_rate=float(data.get("false_alarm_rate", 1e-3)),
                shift=float(data.get("shift", 2.0)),
                ewma_lambda=float(data.get("ewma_lambda", 0.2)),
                severity=SeverityThresholds(**severity),
                severity_overrides={str(k): SeverityThresholds(**v)
                                    for k, v in data.get("severity_overrides", {}).items()},
                noise_floor=float(data.get("noise_floor", 0.01)),
                max_order=int(data.get("max_order", 24)),
                slow_every=int(data.get("slow_every", 0)),
                excitation=str(data.get("excitation", "measured")),
                ssi_orders=None if data.get("ssi_orders") is None else _three_ints(data["ssi_orders"]),
                ssi_block_rows=None if data.get("ssi_block_rows") is None else int(data["ssi_block_rows"]),
                ssi_stability={str(k): float(v) for k, v in data.get("ssi_stability", {}).items()},
            )
        except (KeyError, TypeError, IndexError, ValueError) as exc:
            if isinstance(exc, DataError):
                raise
            msg = f"monitor config is malformed: {type(exc).__name__} {exc}"
            raise DataError(msg) from exc


def _three_ints(values: Sequence[Any]) -> tuple[int, int, int]:
    lo, hi, step = (int(v) for v in values)
    return lo, hi, step


def _labels(name: str) -> str:
    words = {"front": "front bearing", "rear": "rear bearing"}
    if name in words:
        return words[name]
    match = re.fullmatch(r"screw(\d+)", name)
    return f"housing screw {match.group(1)}" if match else name.replace("_", " ")


def default_components(structure: Structure) -> tuple[Component, ...]:
    """Components from the model's elements: direction-suffixed siblings grouped, one per other element.

    Only parameters of kind ``stiffness`` count; elements without one are left out.

    Parameters
    ----------
    structure : Structure
        The model description.

    Returns
    -------
    tuple of Component

    Examples
    --------
    >>> from cappe.model import load_model
    >>> [c.name for c in default_components(load_model("builtin:spindle-bearing"))]
    ['front', 'rear', 'screw1', 'screw2', 'screw3', 'screw4']
    """
    stiffness = {p.name for p in structure.parameters if p.kind == "stiffness"}
    groups: dict[str, list[str]] = {}
    for element in structure.elements:
        names = sorted({str(s) for expr in element.stiffness.values() for s in expr.free_symbols} & stiffness,
                       key=structure.parameter_names.index)
        if not names:
            continue
        key = _DIRECTION_SUFFIX.sub("", element.name)
        members = groups.setdefault(key, [])
        members.extend(n for n in names if n not in members)
    taken: set[str] = set()
    out = []
    for key, names in groups.items():
        free = [n for n in names if n not in taken]
        taken.update(free)
        if free:
            out.append(Component(key, _labels(key), tuple(free)))
    return tuple(out)


def default_config(
    model: NumericModel,
    *,
    machine: str,
    source: str,
    params: Mapping[str, float] | None = None,
    position: Mapping[str, float] | None = None,
    inputs: Sequence[str] | None = None,
    outputs: Sequence[str] | None = None,
    band: tuple[float, float] | None = None,
    components: Sequence[Component] | None = None,
    fault_parameters: Sequence[str] | None = None,
    **settings: Any,
) -> MonitorConfig:
    """A config for ``model`` with defaults derived from it.

    Defaults: every input and output; the band from 0.7 x the first to 1.1 x the last natural frequency of the
    reference model; :func:`default_components`; ``preload`` as a fault parameter when the model has one.
    ``settings`` are the remaining :class:`MonitorConfig` fields.

    Parameters
    ----------
    model : NumericModel
        The compiled model of the machine.
    machine : str
        Machine id.
    source : str
        Model source recorded in the config (``builtin:NAME`` or a YAML path).
    params : mapping name -> float, optional
        Parameter overrides (SI) of the healthy reference.
    position : mapping axis -> float, optional
        Axis position (m or rad) of the measurements.
    inputs, outputs : sequence of str, optional
        Measured FRF channels (default every model input and output).
    band : (float, float), optional
        Analysis band in Hz.
    components : sequence of Component, optional
        Monitored stiffness groups.
    fault_parameters : sequence of str, optional
        Parameters diagnosed on their own.
    **settings
        Other :class:`MonitorConfig` fields (``detection``, ``false_alarm_rate`` ...).

    Returns
    -------
    MonitorConfig

    Raises
    ------
    DataError
        A name is not in the model, or a setting breaks a rule of :class:`MonitorConfig`.
    """
    given = dict(params or {})
    if band is None:
        freq = model.system(given, position).modes("exact").frequency
        band = (round(0.7 * float(freq[0]), 1), round(1.1 * float(freq[-1]), 1))
    if fault_parameters is None:
        fault_parameters = ("preload",) if "preload" in model.parameter_names else ()
    config = MonitorConfig(
        machine=machine,
        model=source,
        params=given,
        position=dict(position or {}),
        inputs=tuple(inputs or model.input_names),
        outputs=tuple(outputs or model.output_names),
        band=band,
        components=tuple(components or default_components(model.structure)),
        fault_parameters=tuple(fault_parameters),
        **settings,
    )
    config.check_model(model)
    return config

"""Condition monitoring (thesis Fig. 1.1): the chain from a measurement to a graded diagnosis, its history store
and dashboard, and the bearing-preload studies behind it.

- machine description: :class:`MonitorConfig` (components: stiffness groups that fail together),
  :func:`default_config`;
- chain: :class:`Monitor` (pre-processing, features, fast and slow parameter estimation, detection, diagnosis,
  severity), :func:`ingest`, :func:`learn_store_baseline`, :func:`register_machine`;
- building blocks: :class:`FactorEstimator`, :func:`modal_features`, :func:`frf_features`, :class:`Baseline`,
  :class:`SequentialDetector` (CUSUM / EWMA designed by ARL), :func:`diagnose` with :class:`FaultHypothesis`;
- history: :class:`HistoryStore` (SQLite or PostgreSQL), dashboard: :func:`make_server`;
- prognosis: :func:`forecast_crossing` (when a degrading component reaches a grade, Fieller interval);
- data: :func:`simulate_scenario` (healthy drift, bearing loss, loosening screw, preload loss), and
  :func:`simulate_operation` (the same as output-only records in production: an unmeasured process force whose
  spectrum changes with the load);
- output-only monitoring (``excitation="operational"``): SSI-COV modes (:func:`cappe.identify.ssi_cov`) and
  :class:`ModalFactorEstimator`;
- preload studies: :func:`preload_map`, :func:`preload_frfs`, :func:`sensor_visibility`, and the quasi-static
  bearing stiffness test :func:`static_bearing_stiffness`.
"""

from cappe.monitor._baseline import BASELINE_FORMAT, RATE_GAP, Baseline, condition_rates, learn_baseline, with_rates
from cappe.monitor._chain import (
    OUTPUT_ONLY_LIMITATIONS,
    Alarm,
    Analysis,
    IngestResult,
    Monitor,
    RecordedFiles,
    detectable_change,
    file_digest,
    forecast_fault,
    ingest,
    learn_store_baseline,
    register_machine,
)
from cappe.monitor._config import (
    CONFIG_FORMAT,
    EXCITATIONS,
    SEVERITY_GRADES,
    Component,
    MonitorConfig,
    SeverityThresholds,
    default_components,
    default_config,
    severity_rank,
    worst_severity,
)
from cappe.monitor._dashboard import DashboardServer, make_server
from cappe.monitor._detection import (
    ChartSignal,
    SequentialDetector,
    cusum_arl,
    cusum_limit,
    ewma_arl,
    ewma_limit,
)
from cappe.monitor._diagnosis import Diagnosis, FaultHypothesis, diagnose
from cappe.monitor._estimation import FactorEstimate, FactorEstimator, ModalFactorEstimator
from cappe.monitor._features import frf_features, modal_features
from cappe.monitor._operation import OperationalMeasurement, operational_response, simulate_operation
from cappe.monitor._preload import THESIS_PRELOADS, PreloadMap, preload_frfs, preload_map, sensor_visibility
from cappe.monitor._prognosis import CrossingForecast, forecast_crossing
from cappe.monitor._scenario import (
    SCENARIO_FORMAT,
    SCENARIOS,
    ScenarioMeasurement,
    ScenarioState,
    read_scenario,
    scenario_states,
    simulate_scenario,
    write_scenario,
)
from cappe.monitor._static import StaticBearingTest, static_bearing_stiffness
from cappe.monitor._store import (
    SCHEMA_VERSION,
    AlarmRecord,
    HistoryStore,
    IngestTransaction,
    MeasurementRecord,
    decode_frf,
    encode_frf,
)

__all__ = [
    "BASELINE_FORMAT",
    "SCHEMA_VERSION",
    "CONFIG_FORMAT",
    "EXCITATIONS",
    "OUTPUT_ONLY_LIMITATIONS",
    "RATE_GAP",
    "SCENARIOS",
    "SCENARIO_FORMAT",
    "SEVERITY_GRADES",
    "THESIS_PRELOADS",
    "Alarm",
    "AlarmRecord",
    "Analysis",
    "Baseline",
    "ChartSignal",
    "Component",
    "CrossingForecast",
    "DashboardServer",
    "Diagnosis",
    "FactorEstimate",
    "FactorEstimator",
    "FaultHypothesis",
    "HistoryStore",
    "IngestTransaction",
    "IngestResult",
    "MeasurementRecord",
    "ModalFactorEstimator",
    "Monitor",
    "MonitorConfig",
    "OperationalMeasurement",
    "PreloadMap",
    "RecordedFiles",
    "ScenarioMeasurement",
    "ScenarioState",
    "SequentialDetector",
    "SeverityThresholds",
    "StaticBearingTest",
    "condition_rates",
    "cusum_arl",
    "cusum_limit",
    "decode_frf",
    "default_components",
    "default_config",
    "detectable_change",
    "diagnose",
    "encode_frf",
    "ewma_arl",
    "ewma_limit",
    "file_digest",
    "forecast_crossing",
    "forecast_fault",
    "frf_features",
    "ingest",
    "learn_baseline",
    "learn_store_baseline",
    "make_server",
    "modal_features",
    "operational_response",
    "preload_frfs",
    "preload_map",
    "read_scenario",
    "scenario_states",
    "register_machine",
    "sensor_visibility",
    "severity_rank",
    "simulate_operation",
    "simulate_scenario",
    "static_bearing_stiffness",
    "with_rates",
    "worst_severity",
    "write_scenario",
]

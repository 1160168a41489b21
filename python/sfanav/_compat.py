"""Old import paths of the flat layout (sfanav 0.1), kept working for one
release: ``import sfanav.metric`` or ``from sfanav.workflow import
Conformer`` still work, with a DeprecationWarning that names the new place.
``MOVED`` is the one table of what moved where (the README's table is made
from it)."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings
from typing import Any

#: old module -> {old name: (new module, new name)}
MOVED: dict[str, dict[str, tuple[str, str]]] = {
    'sfanav.analysis': {
        'EtaValues': ('sfanav.sfa.diagnostics', 'EtaValues'),
        'beta_values': ('sfanav.sfa.node', 'beta_values'),
        'delta_values': ('sfanav.sfa.diagnostics', 'delta_values'),
        'eta_values': ('sfanav.sfa.diagnostics', 'eta_values'),
        'orientation_angles': ('sfanav.sfa.diagnostics', 'orientation_angles'),
        'plot_error_vs_n': ('sfanav.localization.plots', 'plot_error_vs_n'),
        'plot_eta': ('sfanav.sfa.diagnostics', 'plot_eta'),
        'plot_firing_maps': ('sfanav.localization.plots', 'plot_firing_maps'),
        'plot_trajectory': ('sfanav.localization.plots', 'plot_trajectory'),
        'write_report': ('sfanav.localization.report', 'write_report'),
    },
    'sfanav.baselines': {
        'FourierSignature': ('sfanav.localization.baselines', 'FourierSignature'),
        'PerfectMemory': ('sfanav.localization.baselines', 'PerfectMemory'),
        'benchmark': ('sfanav.localization.baselines', 'benchmark'),
    },
    'sfanav.cli': {
        'EXIT_USAGE': ('sfanav.app.cli', 'EXIT_USAGE'),
        'build_parser': ('sfanav.app.cli', 'build_parser'),
        'command': ('sfanav.app.registry', 'command'),
        'main': ('sfanav.app.cli', 'main'),
    },
    'sfanav.dataset': {
        'COLUMNS': ('sfanav.data.schema', 'COLUMNS'),
        'Dataset': ('sfanav.data.dataset', 'Dataset'),
        'DatasetWriter': ('sfanav.data.writer', 'DatasetWriter'),
        'FLOAT_COLUMNS': ('sfanav.data.schema', 'FLOAT_COLUMNS'),
        'FORMAT': ('sfanav.data.schema', 'FORMAT'),
        'INSECT_ENTRIES': ('sfanav.data.schema', 'INSECT_ENTRIES'),
        'INSECT_METADATA': ('sfanav.data.schema', 'INSECT_METADATA'),
        'STR_COLUMNS': ('sfanav.data.schema', 'STR_COLUMNS'),
        'UNITS': ('sfanav.data.schema', 'UNITS'),
        'VERSION': ('sfanav.data.schema', 'VERSION'),
        'read_image': ('sfanav.data.images', 'read_image'),
        'write_dataset': ('sfanav.data.dataset', 'write_dataset'),
        'write_image': ('sfanav.data.images', 'write_image'),
    },
    'sfanav.defaults': {
        'BAND': ('sfanav.localization.recipe', 'BAND'),
        'CAMERA_ELEVATION': ('sfanav.localization.recipe', 'CAMERA_ELEVATION'),
        'NETWORK_PRESET': ('sfanav.localization.recipe', 'NETWORK_PRESET'),
        'READOUT': ('sfanav.localization.recipe', 'READOUT'),
        'default_network': ('sfanav.localization.recipe', 'default_network'),
        'default_rows': ('sfanav.localization.recipe', 'default_rows'),
        'train_default': ('sfanav.localization.training', 'train_default'),
    },
    'sfanav.demo': {
        'DEMO_NETWORK': ('sfanav.app.demo', 'DEMO_NETWORK'),
        'THESIS_5_1_1': ('sfanav.app.demo', 'THESIS_5_1_1'),
        'run_demo': ('sfanav.app.demo', 'run_demo'),
    },
    'sfanav.ekf': {
        'GridSearchResult': ('sfanav.odometry.ekf', 'GridSearchResult'),
        'OdometryEKF': ('sfanav.odometry.ekf', 'OdometryEKF'),
        'ctrv_jacobians': ('sfanav.odometry.ekf', 'ctrv_jacobians'),
        'ctrv_motion': ('sfanav.odometry.ekf', 'ctrv_motion'),
        'grid_search': ('sfanav.odometry.ekf', 'grid_search'),
        'plot_fusion': ('sfanav.odometry.plots', 'plot_fusion'),
    },
    'sfanav.experiments_odometry': {
        'ExperimentResult': ('sfanav.experiments', 'ExperimentResult'),
        'THESIS': ('sfanav.experiments.thesis_5_3', 'THESIS'),
        'compare_solvers': ('sfanav.experiments.synthetic_odometry', 'compare_solvers'),
        'experiment_5_3_1': ('sfanav.experiments.thesis_5_3', 'experiment_5_3_1'),
        'experiment_5_3_2': ('sfanav.experiments.thesis_5_3', 'experiment_5_3_2'),
        'format_rows': ('sfanav.experiments', 'format_rows'),
        'make_line_problem': ('sfanav.experiments.synthetic_odometry', 'make_line_problem'),
        'make_odometry_run': ('sfanav.experiments.synthetic_odometry', 'make_odometry_run'),
        'print_solver_comparison': ('sfanav.experiments.synthetic_odometry', 'print_solver_comparison'),
        'synthetic_features': ('sfanav.experiments.synthetic_odometry', 'synthetic_features'),
    },
    'sfanav.imagerows': {
        'ImageRows': ('sfanav.data.image_rows', 'ImageRows'),
        'band_rows': ('sfanav.data.image_rows', 'band_rows'),
        'horizon_band': ('sfanav.data.image_rows', 'horizon_band'),
        'row_normalize': ('sfanav.data.image_rows', 'row_normalize'),
    },
    'sfanav.localizer': {
        'Localizer': ('sfanav.localization.localizer', 'Localizer'),
        'READOUTS': ('sfanav.localization.localizer', 'READOUTS'),
        'ROTATION_POOLING': ('sfanav.localization.recipe', 'ROTATION_POOLING'),
        'pooled_transform': ('sfanav.localization.localizer', 'pooled_transform'),
        'pooling_step': ('sfanav.localization.localizer', 'pooling_step'),
    },
    'sfanav.metric': {
        'ANGLE_TERMS': ('sfanav.odometry.metric_cost', 'ANGLE_TERMS'),
        'DEFAULT_ODOMETRY_NOISE': ('sfanav.odometry.metric_cost', 'DEFAULT_ODOMETRY_NOISE'),
        'MetricLearner': ('sfanav.odometry.metric_learning', 'MetricLearner'),
        'SOLVERS': ('sfanav.odometry.metric_cost', 'SOLVERS'),
        'metric_cost': ('sfanav.odometry.metric_cost', 'metric_cost'),
        'odometry_variances': ('sfanav.odometry.metric_cost', 'odometry_variances'),
        'plot_metric_lines': ('sfanav.odometry.plots', 'plot_metric_lines'),
    },
    'sfanav.metrics': {
        'Alignment': ('sfanav.localization.error_metrics', 'Alignment'),
        'align': ('sfanav.localization.error_metrics', 'align'),
        'euclidean_errors': ('sfanav.localization.error_metrics', 'euclidean_errors'),
        'localization_metrics': ('sfanav.localization.error_metrics', 'localization_metrics'),
        'mae': ('sfanav.localization.error_metrics', 'mae'),
        'mae_percent': ('sfanav.localization.error_metrics', 'mae_percent'),
        'med': ('sfanav.localization.error_metrics', 'med'),
    },
    'sfanav.modelfile': {
        'FORMAT': ('sfanav.sfa.modelfile', 'FORMAT'),
        'VERSION': ('sfanav.sfa.modelfile', 'VERSION'),
        'load': ('sfanav.sfa.modelfile', 'load'),
        'read_model': ('sfanav.sfa.modelfile', 'read_model'),
        'register_loader': ('sfanav.sfa.modelfile', 'register_loader'),
        'save_model': ('sfanav.sfa.modelfile', 'save_model'),
    },
    'sfanav.network': {
        'DEFAULT_CACHE_LIMIT': ('sfanav.sfa.network', 'DEFAULT_CACHE_LIMIT'),
        'Network': ('sfanav.sfa.network', 'Network'),
        'PRESETS': ('sfanav.sfa.network', 'PRESETS'),
        'Rotation': ('sfanav.sfa.network', 'Rotation'),
        'resolve_config': ('sfanav.sfa.network', 'resolve_config'),
        'spatial_pairs': ('sfanav.sfa.pairs', 'spatial_pairs'),
    },
    'sfanav.readout': {
        'AUTO_BLOCK': ('sfanav.localization.readout_selection', 'AUTO_BLOCK'),
        'AUTO_FOLDS': ('sfanav.localization.readout_selection', 'AUTO_FOLDS'),
        'AUTO_MAX_CV_SAMPLES': ('sfanav.localization.readout_selection', 'AUTO_MAX_CV_SAMPLES'),
        'AUTO_TOLERANCE': ('sfanav.localization.readout_selection', 'AUTO_TOLERANCE'),
        'GPReadout': ('sfanav.localization.readouts', 'GPReadout'),
        'KNNReadout': ('sfanav.localization.readouts', 'KNNReadout'),
        'KernelRidgeReadout': ('sfanav.localization.readouts', 'KernelRidgeReadout'),
        'ReadoutSelection': ('sfanav.localization.readout_selection', 'ReadoutSelection'),
        'auto_candidates': ('sfanav.localization.readout_selection', 'auto_candidates'),
        'block_folds': ('sfanav.localization.readout_selection', 'block_folds'),
        'default_candidates': ('sfanav.localization.readout_selection', 'default_candidates'),
        'describe_spec': ('sfanav.localization.readouts', 'describe_spec'),
        'make_readout': ('sfanav.localization.readouts', 'make_readout'),
        'readout_from_state': ('sfanav.localization.readouts', 'readout_from_state'),
        'readout_state': ('sfanav.localization.readouts', 'readout_state'),
        'select_auto_readout': ('sfanav.localization.readout_selection', 'select_auto_readout'),
        'select_readout': ('sfanav.localization.readout_selection', 'select_readout'),
    },
    'sfanav.regression': {
        'ErrorCurve': ('sfanav.localization.protocols', 'ErrorCurve'),
        'QuadraticRegression': ('sfanav.localization.quadratic', 'QuadraticRegression'),
        'RANDOM_SPLITS': ('sfanav.localization.protocols', 'RANDOM_SPLITS'),
        'RegressionResult': ('sfanav.localization.protocols', 'RegressionResult'),
        'TEST_RUN': ('sfanav.localization.protocols', 'TEST_RUN'),
        'error_vs_n': ('sfanav.localization.protocols', 'error_vs_n'),
        'evaluate_random_splits': ('sfanav.localization.protocols', 'evaluate_random_splits'),
        'evaluate_test_run': ('sfanav.localization.protocols', 'evaluate_test_run'),
    },
    'sfanav.unwarp': {
        'Mirror': ('sfanav.data.unwarp', 'Mirror'),
        'Unwarper': ('sfanav.data.unwarp', 'Unwarper'),
        'estimate_mirror': ('sfanav.data.unwarp', 'estimate_mirror'),
    },
    'sfanav.workflow': {
        'Conformer': ('sfanav.data.preprocessing', 'Preprocessor'),
        'Evaluation': ('sfanav.localization.evaluation', 'Evaluation'),
        'IMAGE_SUFFIXES': ('sfanav.data.sources', 'IMAGE_SUFFIXES'),
        'ImageSource': ('sfanav.data.sources', 'ImageSource'),
        'Log': ('sfanav._progress', 'Log'),
        'Preprocessing': ('sfanav.data.preprocessing', 'Preprocessing'),
        'VIDEO_SUFFIXES': ('sfanav.data.sources', 'VIDEO_SUFFIXES'),
        'coordinate_range': ('sfanav.localization.evaluation', 'coordinate_range'),
        'evaluate': ('sfanav.localization.evaluation', 'evaluate'),
        'evaluation_rows': ('sfanav.localization.evaluation', 'evaluation_rows'),
        'fit_localizer': ('sfanav.localization.training', 'fit_localizer'),
        'load_run': ('sfanav.data.sources', 'load_run'),
        'metrics_json': ('sfanav.localization.evaluation', 'metrics_json'),
        'open_images': ('sfanav.data.sources', 'open_images'),
        'random_splits_readout': ('sfanav.localization.evaluation', 'random_splits_readout'),
        'select_run': ('sfanav.data.sources', 'select_run'),
        'stderr_log': ('sfanav._progress', 'stderr_log'),
        'write_evaluation_report': ('sfanav.localization.evaluation', 'write_evaluation_report'),
    },
}


class MovedModule(types.ModuleType):
    """A stand-in for an old module: each attribute is looked up at its new
    place."""

    def __getattr__(self, name: str) -> Any:
        names = MOVED[self.__name__]
        if name not in names:
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r} (sfanav's modules moved: "
                                 "see the README's table of moves)")
        module, new = names[name]
        return getattr(importlib.import_module(module), new)

    def __dir__(self) -> list[str]:
        return sorted(MOVED[self.__name__])


class MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old module names of :data:`MOVED`."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> Any:
        if fullname not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: Any) -> types.ModuleType:
        return MovedModule(spec.name)

    def exec_module(self, module: types.ModuleType) -> None:
        targets = sorted({m for m, _ in MOVED[module.__name__].values()})
        warnings.warn(f"{module.__name__} moved to {', '.join(targets)}; the old path goes away in the next release",
                      DeprecationWarning, stacklevel=3)


def install() -> None:
    """Adds :class:`MovedFinder` to ``sys.meta_path`` (once)."""
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(MovedFinder())

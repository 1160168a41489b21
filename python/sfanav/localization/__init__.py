"""Stage 3: slow features -> metric position.

* :class:`Localizer`: a trained network, its image rows and a readout, saved
  as one model file;
* readouts: :class:`QuadraticRegression` (the thesis's, 3.5), the GP,
  kernel-ridge and kNN readouts (:mod:`~sfanav.localization.readouts`) and
  their blocked cross-validated choice
  (:mod:`~sfanav.localization.readout_selection`);
* :mod:`~sfanav.localization.recipe`: the training recipes (the thesis's and
  the sfanav default) in one place; :func:`fit_localizer` (the recipe
  applied to a run: :func:`sfanav.pipeline.train_localizer`);
* evaluation: error metrics (:mod:`~sfanav.localization.error_metrics`),
  protocols (:mod:`~sfanav.localization.protocols`), :func:`evaluate`, the
  baselines a user might pick instead (:class:`PerfectMemory`,
  :class:`FourierSignature`), plots and reports.
"""

from __future__ import annotations

from .baselines import FourierSignature, PerfectMemory, benchmark, fourier_signature
from .error_metrics import (
    Alignment,
    align,
    euclidean_errors,
    localization_metrics,
    mae,
    mae_percent,
    med,
)
from .evaluation import Evaluation, evaluate, evaluation_rows
from .localizer import Localizer, pooled_transform, pooling_step
from .plots import plot_error_vs_n, plot_firing_maps, plot_trajectory
from .protocols import (
    RANDOM_SPLITS,
    TEST_RUN,
    ErrorCurve,
    RegressionResult,
    error_vs_n,
    evaluate_random_splits,
    evaluate_test_run,
)
from .quadratic import QuadraticRegression
from .readout_selection import (
    AUTO_BLOCK,
    AUTO_FOLDS,
    AUTO_TOLERANCE,
    ReadoutSelection,
    auto_candidates,
    block_folds,
    cross_val_predict,
    default_candidates,
    group_folds,
    select_auto_readout,
    select_readout,
)
from .readouts import (
    GPReadout,
    KernelRidgeReadout,
    KNNReadout,
    make_readout,
    readout_from_state,
    readout_state,
)
from .recipe import (
    BAND,
    NETWORK_PRESET,
    READOUT,
    SIGNATURE,
    Recipe,
    default_network,
    default_rows,
    pooling_for,
    recipe_for,
)
from .report import write_report
from .signature_knn import SignatureKNNReadout
from .signature_readout import SignatureGPReadout
from .training import fit_localizer

__all__ = ["cross_val_predict", "AUTO_BLOCK", "AUTO_FOLDS", "AUTO_TOLERANCE", "Alignment", "BAND", "ErrorCurve", "Evaluation", "FourierSignature", "GPReadout", "KNNReadout", "KernelRidgeReadout", "Localizer", "NETWORK_PRESET", "PerfectMemory", "QuadraticRegression", "RANDOM_SPLITS", "READOUT", "Recipe", "ReadoutSelection", "SignatureGPReadout", "SignatureKNNReadout", "group_folds", "fourier_signature", "SIGNATURE", "RegressionResult", "TEST_RUN", "align", "auto_candidates", "benchmark", "block_folds", "default_candidates", "default_network", "default_rows", "error_vs_n", "euclidean_errors", "evaluate", "evaluate_random_splits", "evaluate_test_run", "evaluation_rows", "fit_localizer", "localization_metrics", "mae", "mae_percent", "make_readout", "med", "plot_error_vs_n", "plot_firing_maps", "plot_trajectory", "pooled_transform", "pooling_step", "readout_from_state", "pooling_for", "readout_state", "recipe_for", "select_auto_readout", "select_readout", "write_report"]

"""The training recipes, in one place: what the thesis's configuration and the
sfanav default mean for the readout, the image rows, the number of outputs
and rotation pooling.

* **thesis** (a ``thesis-*`` preset): all image rows, a quadratic regression
  of the 8 slowest outputs, no rotation pooling;
* **sfanav default** (the ``sfanav-default`` preset): the horizon band
  (elevation -10 .. +20 degrees, :func:`default_rows`), rotation pooling
  over 8 rotations, and the ``"auto"`` readout of the slowest outputs
  together with the panorama's Fourier signature (:data:`SIGNATURE`);
  robustness to what a robot's camera does to its images
  (:data:`ROBUSTNESS`, default :data:`DEFAULT_ROBUSTNESS`): the photometric
  normalisation, a readout fitted on corrupted copies as well and a network
  trained to ignore the corruptions.

:func:`recipe_for` resolves a recipe from what the user named (a preset, a
config file, explicit overrides); ``sfanav train``,
:func:`sfanav.pipeline.train_localizer` and :class:`sfanav.Localizer` all
ask it; :meth:`Recipe.fit_kwargs` turns it into the arguments of
:func:`sfanav.localization.fit_localizer`. Why these choices:
docs/gardens.md, docs/robustness.md."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from .._checks import check_int
from ..data.corruptions import CAMERA, CorruptionModel
from ..data.image_rows import ImageRows
from ..data.photometric import lowpass_for
from ..sfa.network import Network

NETWORK_PRESET = "sfanav-default"
"""The network preset of the sfanav default."""
BAND = (-10.0, 20.0)
"""The default image rows: elevation band in degrees (lowest, highest)."""
READOUT = "auto"
"""The default readout (chosen by blocked cross-validation)."""
CAMERA_ELEVATION = (-30.0, 20.0)
"""Elevation range (degrees) of the simulator's and the thesis's panoramas, assumed when a dataset does not say."""
ROTATION_POOLING = 8
"""Rotations the features are averaged over under ``rotation_pooling="auto"`` with a non-quadratic readout."""
SIGNATURE = "fourier"
"""The appearance signature the sfanav default reads beside the slow features."""
SIGNATURES = ("fourier",)
"""The appearance signatures a :class:`sfanav.Localizer` can read."""
SIGNATURE_COEFFICIENTS = 15
"""Fourier coefficients per image row and channel of the ``"fourier"`` signature (as the Fourier-signature peer)."""
THESIS_N_OUTPUTS = 8
"""Slow features the thesis's quadratic regression reads."""

ROBUSTNESS = ("none", "light", "standard", "full")
"""How the sfanav default guards against what a robot's camera and image transport do to its images
(JPEG, noise, blur, exposure, ...; docs/robustness.md):

* ``"none"``: nothing (the thesis; the sfanav default before the corruption study);
* ``"light"``: the photometric normalisation (:data:`PHOTOMETRIC`: a 2 px low-pass, its rows 2.5 deg of elevation
  (:func:`sfanav.data.photometric.lowpass_for`), then log intensities
  with a flat field and a fixed contrast, so that exposure, white balance, gamma and vignetting do not
  move the features and JPEG, noise and defocus move them less) and a readout fitted on the run and on a
  copy of it corrupted as a robot camera may (:data:`sfanav.data.corruptions.CAMERA`);
* ``"standard"`` (the default): ``"light"`` and a network trained to ignore those corruptions, each
  image's rotation interleaved with a corrupted copy at weight :data:`INVARIANCE_WEIGHTS` ``["standard"]``;
* ``"full"``: the same at weight 1: holds under every corruption measured, at a larger cost in
  precision on flawless images.
"""
INVARIANCE_WEIGHTS = {"standard": 0.25, "full": 1.0}
"""The weight of the invariance partners per robustness level (0.25 chosen on four gardens:
docs/robustness.md)."""
DEFAULT_ROBUSTNESS = "standard"
"""The sfanav default's robustness (:data:`ROBUSTNESS`)."""
PHOTOMETRIC = "lowpass-log-contrast"
"""The photometric normalisation of every robustness level but ``"none"``
(:func:`sfanav.data.photometric.lowpass_log_contrast`; chosen over ``"log-contrast"`` on four gardens:
docs/robustness.md)."""

ROWS = ("band", "all")
SUPERVISION = ("auto", "ground-truth", "odometry")
"""What the readout is fitted to: ground-truth positions, or positions learned from the run's odometry."""


@dataclass(frozen=True)
class Recipe:
    """How a localizer is trained on top of a network.

    Attributes
    ----------
    name : str
        ``"thesis"``, ``"sfanav default"`` or ``"custom"``.
    readout : "auto", "quadratic" or a readout spec dict
    rows : "band" or "all"
        The horizon band (:data:`BAND`) or every image row.
    n_outputs : int or None
        Slow features the readout reads (None: the readout's choice).
    rotation_pooling : "auto", int or None
        As :class:`sfanav.Localizer` takes it; :func:`pooling_for` resolves it.
    signature : "fourier" or None
        The appearance signature read beside the slow features.
    robustness : one of :data:`ROBUSTNESS`
        What guards the localizer against camera corruptions.
    """

    name: str
    readout: Any
    rows: str
    n_outputs: int | None
    rotation_pooling: Any = "auto"
    signature: str | None = None
    robustness: str = "none"

    def image_rows(self, camera_elevation: Sequence[float] | None = None) -> ImageRows | None:
        """The :class:`ImageRows` step for panoramas whose rows span
        ``camera_elevation`` (degrees; default :data:`CAMERA_ELEVATION`), or
        None for all rows."""
        if self.rows == "all":
            return None
        return default_rows(CAMERA_ELEVATION if camera_elevation is None else camera_elevation)

    def info(self) -> dict[str, Any]:
        """What the model file records about the recipe."""
        out: dict[str, Any] = {"configuration": "sfanav default"} if self.name == "sfanav default" else {}
        if self.robustness != "none":
            out["robustness"] = self.robustness
        return out

    def robust_kwargs(self, model: CorruptionModel = CAMERA) -> dict[str, Any]:
        """The :func:`~sfanav.localization.fit_localizer` arguments of the
        recipe's robustness: ``photometric``, ``readout_augmentation``,
        ``invariance`` (corruptions drawn from ``model``) and
        ``invariance_weight``."""
        r = self.robustness
        weight = INVARIANCE_WEIGHTS.get(r)
        return {"photometric": PHOTOMETRIC if r != "none" else None,
                "readout_augmentation": model if r != "none" else None,
                "invariance": model if weight else None, "invariance_weight": weight or 1.0}

    def fit_kwargs(self, camera_elevation: Sequence[float] | None = None,
                   height: int | None = None) -> dict[str, Any]:
        """Every :func:`~sfanav.localization.fit_localizer` argument the recipe
        decides (readout, rows for panoramas spanning ``camera_elevation``,
        n_outputs, rotation pooling, signature and robustness, and for
        panoramas of ``height`` rows the photometric low-pass's widths,
        :func:`sfanav.data.photometric.lowpass_for`): one place, so that
        ``sfanav train``, the demo and the experiments train alike."""
        out = {"readout": self.readout, "rows": self.image_rows(camera_elevation), "n_outputs": self.n_outputs,
               "rotation_pooling": self.rotation_pooling, "signature": self.signature, **self.robust_kwargs()}
        if height is not None and out["photometric"] == "lowpass-log-contrast":  # the rows in degrees of elevation
            out["lowpass"] = lowpass_for(CAMERA_ELEVATION if camera_elevation is None else camera_elevation, height)
        return out


def recipe_for(preset: str | None = None, *, config: bool = False, readout: Any = None, rows: str | None = None,
               n_outputs: int | None = None, rotation_pooling: Any = None, signature: Any = "auto",
               robustness: str | None = None) -> Recipe:
    """The recipe for a network chosen by ``preset`` (a name) or by a config
    file (``config=True``), with the user's explicit choices on top (None:
    the recipe decides). A ``thesis-*`` preset gets the thesis's recipe (all
    rows, quadratic regression of 8 outputs, no pooling); the sfanav default
    (no preset and no config, or the ``sfanav-default`` preset) the horizon
    band, the ``"auto"`` readout and pooling; a config file the ``"auto"``
    readout on all rows. ``signature``: ``"auto"`` reads the Fourier
    signature beside the slow features with the ``"auto"`` readout of the
    sfanav default (:data:`SIGNATURE`), none otherwise; None or
    ``"fourier"`` as given. ``robustness`` (:data:`ROBUSTNESS`): None takes
    :data:`DEFAULT_ROBUSTNESS` for the sfanav default and ``"none"`` for the
    thesis's recipe and config files."""
    if rows is not None and rows not in ROWS:
        raise ValueError(f"rows must be one of {ROWS}, got {rows!r}")
    if n_outputs is not None:
        n_outputs = check_int(n_outputs, "n_outputs")
    thesis = preset is not None and preset.startswith("thesis-")
    default = not config and not thesis
    readout = readout or ("quadratic" if thesis else READOUT)
    rows = rows or ("band" if default else "all")
    if n_outputs is None and readout == "quadratic":
        n_outputs = THESIS_N_OUTPUTS
    if isinstance(signature, str) and signature == "auto":
        signature = SIGNATURE if default and readout == READOUT else None
    elif signature is not None and signature not in SIGNATURES:
        raise ValueError(f"signature must be 'auto', one of {SIGNATURES} or None, got {signature!r}")
    if robustness is None:
        robustness = DEFAULT_ROBUSTNESS if default else "none"
    elif robustness not in ROBUSTNESS:
        raise ValueError(f"robustness must be one of {ROBUSTNESS}, got {robustness!r}")
    if default and readout == READOUT and rows == "band" and signature == SIGNATURE and robustness == DEFAULT_ROBUSTNESS:
        name = "sfanav default"
    elif thesis and readout == "quadratic" and rows == "all" and robustness == "none":
        name = "thesis"
    else:
        name = "custom"
    return Recipe(name, readout, rows, n_outputs, "auto" if rotation_pooling is None else rotation_pooling, signature,
                  robustness)


def pooling_for(readout: Any, rotation_pooling: Any, *, has_network: bool = True) -> int:
    """How many rotations the features are averaged over: ``"auto"`` means
    none with the thesis's quadratic readout or without a network (the
    caller's own features), else :data:`ROTATION_POOLING`; None means none;
    an integer is taken as it is (>= 1)."""
    p = rotation_pooling
    if p is None or (isinstance(p, str) and p == "auto" and not has_network):
        return 1
    if isinstance(p, str):
        if p != "auto":
            raise ValueError(f"rotation_pooling must be 'auto', a positive integer or None, got {p!r}")
        return 1 if (isinstance(readout, str) and readout == "quadratic") else ROTATION_POOLING
    return check_int(p, "rotation_pooling")


def default_network(**overrides: Any) -> Network:
    """An unfitted network of the ``sfanav-default`` preset (350x40 RGB
    input); ``overrides`` as :meth:`sfanav.Network.from_preset`."""
    return Network.from_preset(NETWORK_PRESET, **overrides)


def default_rows(camera_elevation: Sequence[float] = CAMERA_ELEVATION) -> ImageRows:
    """The default image rows: the horizon band (:data:`BAND`) of panoramas
    whose rows span ``camera_elevation`` (degrees, lowest, highest;
    equiangular rows, row 0 highest)."""
    lo, hi = (float(v) for v in camera_elevation)
    return ImageRows(band=BAND, camera_elevation=(lo, hi))


def supervision_for(requested: str | None, *, has_ground_truth: bool, has_odometry: bool) -> str:
    """``"ground-truth"`` or ``"odometry"``: what a run's readout is fitted to.
    ``"auto"`` (or None) takes ground truth where the run has it for every
    frame, else its odometry. ValueError when the run lacks what is asked
    for, naming the way out."""
    requested = requested or "auto"
    if requested not in SUPERVISION:
        raise ValueError(f"supervision must be one of {SUPERVISION}, got {requested!r}")
    if requested == "auto":
        if has_ground_truth:
            return "ground-truth"
        if has_odometry:
            return "odometry"
        raise ValueError("the run has neither ground-truth x, y nor odometry for every frame: the readout needs one")
    if requested == "ground-truth" and not has_ground_truth:
        raise ValueError("the run lacks ground-truth x, y for some frames: train with supervision 'odometry' "
                         "(positions learned from the run's odometry) instead")
    if requested == "odometry" and not has_odometry:
        raise ValueError("the run lacks odometry (odom_x, odom_y, odom_heading) for some frames: supervision "
                         "'odometry' needs it for every frame")
    return requested

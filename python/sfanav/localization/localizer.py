"""``sfanav.Localizer``: a trained network, its image rows and the readout from
its slow features to metric positions, saved and loaded as one model file.

``readout="auto"`` (the sfanav default) chooses among a GP with one length
scale per output, Gaussian kernel ridge and kNN by blocked cross-validation
on the training run, and then reads position from *rotation pooled*
features: the network's outputs averaged over evenly spaced rotations of
the panorama. ``readout="quadratic"`` is the thesis's quadratic regression
of the 8 slowest outputs (3.5, 5.1-5.2), without pooling. Which pooling goes
with which readout is decided in :mod:`sfanav.localization.recipe`."""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import (
    NotFittedError,
    as_matrix,
    as_real_array,
    check_finite,
    check_int,
    check_n_outputs,
    check_nonneg_float,
    check_same_length,
    is_single_image,
)
from ..data.image_rows import ImageRows
from ..data.photometric import PHOTOMETRIC
from ..data.photometric import lowpass_widths
from ..data.photometric import normalize as photometric_normalize
from ..sfa.modelfile import read_model, register_loader, save_model
from ..sfa.network import Network
from .error_metrics import euclidean_errors, localization_metrics
from .quadratic import QuadraticRegression
from .readout_selection import select_auto_readout
from .baselines import fourier_signature
from .novelty import NoveltyReference
from .readouts import make_readout, readout_from_state, readout_state
from .recipe import SIGNATURE_COEFFICIENTS, SIGNATURES, pooling_for

READOUTS = ("auto", "quadratic")




def pooling_step(network: Network, width: int, k: int) -> int:
    """The rotation step (px) of rotation pooling over ``k`` rotations of
    ``width``-px panoramas: the smallest step >= ceil(width / k) that is
    coprime with the network's receptive-field grid period (the product of
    its layers' horizontal strides), so the pooled rotations see the grid at
    different alignments (why: docs/localization.md, rotation pooling). The
    rotations are then ceil(width / step) <= k."""
    base = -(-int(width) // int(k))
    period = 1
    for layer in network.config_["layers"]:
        period *= int(layer["stride"][0])
    for step in range(base, int(width)):
        if math.gcd(step, period) == 1:
            return step
    return base


def pooled_transform(network: Network, images: Any, k: int) -> np.ndarray:
    """``network``'s outputs of images (N, H, W[, C]) or one image, averaged
    over ``k`` rotations of each panorama in steps of
    :func:`pooling_step` px: (N, n) or (n,)."""
    a = np.asarray(images)
    single = is_single_image(a, network.input_shape[2])
    width = a.shape[1] if single else (a.shape[2] if a.ndim >= 3 else 0)
    if width < k:
        raise ValueError(f"rotation_pooling={k} needs panoramas at least {k} px wide, got {width} px")
    return network.transform(a, rotations=True, step=pooling_step(network, width, k)).mean(axis=-2)



def _training_predictions(readout: Any, X: np.ndarray) -> np.ndarray:
    """The readout's estimates at the samples it was just fitted on: its
    ``training_predictions_`` where it has them for all of ``X`` (a GP's
    posterior mean from the fit, no second distance pass), else
    ``predict(X)``."""
    P = getattr(readout, "training_predictions_", None)
    return P if P is not None and len(P) == len(X) else readout.predict(X)

class Localizer:
    """Absolute position from one panoramic image: slow features of a trained
    :class:`sfanav.Network`, then a readout of the slowest ones to metric
    (x, y).

    Parameters
    ----------
    network : Network or None
        A fitted network. None for a features-only localizer (use
        :meth:`fit_features` / :meth:`predict_features`, e.g. with features
        stacked from several networks).
    n_outputs : int or None, default None
        Number of slowest outputs read out. None: with ``readout="auto"``
        8 or 12 (whichever the cross-validation prefers; those the network
        has), with ``"quadratic"`` 8 (the thesis's best n).
    ridge : float, default 0.0
        L2 penalty of the quadratic regression (0: ordinary least squares).
    degree : int, default 2
        Degree of the quadratic regression's expansion (2: the thesis's).
    readout : {"auto", "quadratic"} or dict, default "auto"
        ``"auto"``: the sfanav default, a GP readout (ARD kernel, marginal
        likelihood) unless Gaussian kernel ridge or kNN is more than 10 %
        better by blocked cross-validation on the training data
        (:func:`sfanav.localization.select_auto_readout`); ``"quadratic"``:
        the thesis's quadratic regression (with ``ridge``, ``degree``); a
        dict: one readout spec (:func:`sfanav.localization.make_readout`, e.g.
        ``{"kind": "knn", "n_outputs": 8, "k": 3}``).
    rows : ImageRows or None, default None
        Row handling applied to images before the network
        (:class:`sfanav.data.ImageRows`, e.g. the sfanav default's
        horizon band); it must be what the network was trained on
        (:func:`sfanav.localization.fit_localizer` takes care of that).
    rotation_pooling : "auto", int or None, default "auto"
        Rotation pooling (group averaging over the panorama's rotations): an
        image's features are the network's outputs averaged over K rotations
        of the panorama in steps of about W / K px (W its width; the step
        :func:`pooling_step` picks), so the readout sees features that no
        longer depend on the heading (the network is only approximately
        invariant: eta_phi > 0). About 3x the network's work per image
        for K = 8 (the core shares the lower layers across rotations).
        ``"auto"``: K = 8 (the sfanav default; docs/gardens.md) unless
        ``readout="quadratic"`` (the thesis's configuration: no pooling);
        None or 1: no pooling.
    signature : {"fourier"} or None, default None
        An appearance signature read beside the slow features: ``"fourier"``,
        the rotation-invariant Fourier signature of the panorama as it is
        given (every row and channel, :data:`SIGNATURE_COEFFICIENTS`
        coefficients, fewer on panoramas under 28 px wide;
        :func:`sfanav.localization.fourier_signature`). The
        readout is then :class:`sfanav.localization.SignatureGPReadout`
        (``readout="auto"``: the slow features with the signature, or the
        signature alone, by marginal likelihood; with several recordings,
        ``fit_features(groups=)``, the nearest training views by the
        signature, :class:`sfanav.localization.SignatureKNNReadout`, if
        clearly better with one recording held out). The sfanav default sets it
        (:func:`sfanav.localization.recipe_for`); it stores the signature of
        every training place (docs/gardens.md).
    photometric : {"log-contrast", "lowpass-log-contrast"} or None, default None
        A photometric normalisation applied to every image first, before
        the rows, the network and the signature
        (:func:`sfanav.data.photometric.log_contrast`: the log intensities
        centred per channel and scaled to a fixed contrast, so that exposure,
        white balance and gamma do not move the features;
        :func:`sfanav.data.photometric.lowpass_log_contrast`: the same after
        a 2 px Gaussian low-pass, with a flat field that removes vignetting).
        It must be what
        the network was trained on (:func:`fit_localizer` takes care of
        that); the sfanav default sets it (docs/robustness.md).
    lowpass : float, (float, float) or None, default None
        The low-pass widths in pixels, (rows, columns), of
        ``photometric="lowpass-log-contrast"`` (None: 2 px on both; the
        sfanav default scales the rows' width to the panorama's elevation
        span, :func:`sfanav.data.photometric.lowpass_for`).

    Attributes
    ----------
    regression_ : QuadraticRegression, GPReadout, KernelRidgeReadout or KNNReadout
        The fitted readout (``predict(features)`` -> (N, 2) metres).
    readout_spec_ : dict
        Its spec (kind, n_outputs and hyperparameters).
    n_outputs_ : int
        Slowest outputs the fitted readout uses.
    selection_ : ReadoutSelection or None
        With ``readout="auto"``: the cross-validation (candidates, errors,
        the rule that decided); not saved in the model file.
    rotation_pooling_ : int
        Rotations averaged per image (1: none).
    n_signature_ : int
        Values of the appearance signature the readout reads (0: none).
    n_features_in_ : int
        Feature columns seen in fit.
    train_metrics_ : dict
        :func:`sfanav.localization.localization_metrics` on the training data
        (optimistic; evaluate on a separate test run).
    training_positions_ : ndarray (N, 2)
        The positions (metres) the readout was fitted to, in the model's map:
        ground truth, or the positions learned from odometry
        (:func:`sfanav.odometry.learn_positions`). Saved in the model file;
        :func:`sfanav.navigation.navigate` builds its geodesic field over
        them. ``None`` for a model file written before they were stored.
    novelty_ : NoveltyReference or None
        The training run's slowest features, against which :meth:`novelty`
        scores a query (:class:`sfanav.localization.novelty.NoveltyReference`).
        Saved in the model file; ``None`` for a file written before it was
        stored.
    info : dict
        Free JSON metadata saved with the model (the ``sfanav`` command
        stores the image preprocessing and training settings here).

    Examples
    --------
    >>> loc = sfanav.Localizer(net, n_outputs=8).fit(train_images, train_xy)  # doctest: +SKIP
    >>> xy = loc.predict(test_images)           # (N, 2) metres              # doctest: +SKIP
    >>> loc.evaluate(test_images, test_xy)["med"]                            # doctest: +SKIP
    >>> loc.save("garden.sfa"); loc = sfanav.load("garden.sfa")             # doctest: +SKIP
    """

    def __init__(self, network: Network | None, n_outputs: int | None = None, ridge: float = 0.0, degree: int = 2,
                 readout: str | dict[str, Any] = "auto", rows: ImageRows | None = None,
                 rotation_pooling: int | str | None = "auto", signature: str | None = None,
                 photometric: str | None = None, lowpass: Any = None) -> None:
        if network is not None and not isinstance(network, Network):
            raise TypeError(f"network must be a sfanav.Network or None, got {type(network).__name__}")
        if rows is not None and not isinstance(rows, ImageRows):
            raise TypeError(f"rows must be a sfanav.data.ImageRows or None, got {type(rows).__name__}")
        self.network = network
        self.n_outputs = n_outputs
        self.ridge = ridge
        self.degree = degree
        self.readout = readout
        self.rows = rows
        self.rotation_pooling = rotation_pooling
        self.signature = signature
        self.photometric = photometric
        self.lowpass = lowpass
        self.info: dict[str, Any] = {}
        self.readout_memory_: Any = None
        self.novelty_: NoveltyReference | None = None

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {"network": self.network, "n_outputs": self.n_outputs, "ridge": self.ridge, "degree": self.degree,
                "readout": self.readout, "rows": self.rows, "rotation_pooling": self.rotation_pooling,
                "signature": self.signature, "photometric": self.photometric, "lowpass": self.lowpass}

    def __repr__(self) -> str:
        net = "None" if self.network is None else repr(self.network)
        state = f"fitted: {self.describe_readout()}" if self.is_fitted_ else "not fitted"
        ro = self.readout if isinstance(self.readout, str) else "spec"
        rows = "" if self.rows is None or self.rows.identity else f", rows={self.rows.describe()!r}"
        pool = "" if self.rotation_pooling == "auto" else f", rotation_pooling={self.rotation_pooling!r}"
        pool += "" if self.signature is None else f", signature={self.signature!r}"
        pool += "" if self.photometric is None else f", photometric={self.photometric!r}"
        pool += "" if self.lowpass is None else f", lowpass={self.lowpass!r}"
        return (f"<sfanav.Localizer readout={ro!r}, n_outputs={self.n_outputs}{rows}{pool}, {state}, "
                f"network={net}>")

    def describe_readout(self) -> str:
        """The fitted readout in words, e.g. ``kernel(n_outputs=12, gamma=0.5, alpha=0.001)``."""
        from .readouts import describe_spec

        return describe_spec(self.readout_spec_) if self.is_fitted_ else "not fitted"

    @property
    def is_fitted_(self) -> bool:
        return hasattr(self, "regression_")

    # ------------------------------------------------------------ features
    def trained_network(self) -> Network:
        """The fitted network; ValueError if this localizer works on
        precomputed features, NotFittedError if the network is not fitted."""
        if self.network is None:
            raise ValueError(
                "this Localizer has no network: use fit_features/predict_features with precomputed features"
            )
        if not self.network.is_fitted_:
            raise NotFittedError("the Localizer's network is not fitted; fit the network first")
        return self.network

    def features(self, images: Any, *, rotations: bool = False) -> np.ndarray:
        """The features the readout sees of images (N, H, W[, C]): the
        network's slow features (after ``rows``), rotation pooled if
        :attr:`rotation_pooling_` > 1; (N, n), or (H, W[, C]) -> (n,).

        ``rotations=True``: (N, K, n) under the K simulated rotations (the
        training step), for a localizer without pooling only (pooled
        features are already averaged over rotations)."""
        net = self.trained_network()
        a = np.asarray(images)
        one = is_single_image(a, net.input_shape[2])
        images = self.network_input(a[None] if one else a)
        return self.transform_rows(images[0] if one else images, rotations=rotations)

    def normalized(self, images: Any) -> Any:
        """Images (N, H, W[, C]) after the localizer's photometric
        normalisation (as given without one): what its rows and signature
        start from."""
        return photometric_normalize(images, self._check_photometric(), lowpass=self.photometric_lowpass())

    def network_input(self, images: Any) -> Any:
        """What the network sees of images (N, H, W[, C]): the photometric
        normalisation, then the rows (:meth:`transform_rows` takes it)."""
        a = self.normalized(images)
        if self.rows is not None and not self.rows.identity:
            a = self.rows(a)
        return a

    def _check_photometric(self) -> str | None:
        if self.photometric is not None and self.photometric not in PHOTOMETRIC:
            raise ValueError(f"photometric must be one of {PHOTOMETRIC} or None, got {self.photometric!r}")
        return self.photometric

    def photometric_lowpass(self) -> tuple[float, float] | None:
        """The low-pass widths (rows, columns) in pixels of ``photometric="lowpass-log-contrast"`` when they are
        not the default's 2 px (None then, and without ``lowpass``); ValueError for bad widths, or widths without
        that normalisation."""
        if self.lowpass is None:
            return None
        pair = lowpass_widths(self.lowpass)
        if self._check_photometric() != "lowpass-log-contrast":
            raise ValueError(f"lowpass needs photometric='lowpass-log-contrast', got {self.photometric!r}")
        return None if pair == lowpass_widths(None) else pair

    def transform_rows(self, images: Any, *, rotations: bool = False) -> np.ndarray:
        """As :meth:`features` for images the localizer's ``rows`` were
        already applied to (what its network sees)."""
        net = self.trained_network()
        k = self._pooling()
        if k == 1:
            return net.transform(images, rotations=rotations)
        if rotations:
            raise ValueError(
                f"this Localizer averages its features over {k} rotations already (rotation_pooling); "
                "rotations=True needs a localizer without pooling (rotation_pooling=None)"
            )
        return pooled_transform(net, images, k)

    def signatures(self, images: Any) -> np.ndarray:
        """The appearance signatures the readout reads beside the slow
        features, of images (N, H, W[, C]) as given (before ``rows``):
        (N, q) float32, or (q,) for one image. ValueError if this localizer
        reads none (``signature=None``). The signature is of the images after
        the photometric normalisation, before ``rows``."""
        kind = self._check_signature()
        if kind is None:
            raise ValueError("this Localizer reads no appearance signature (signature=None)")
        net = self.trained_network() if self.network is not None else None
        a = np.asarray(images)
        one = net is not None and is_single_image(a, net.input_shape[2])
        batch = self.normalized(a[None] if one else a)
        width = batch.shape[2] if batch.ndim >= 3 else 0
        G = fourier_signature(batch, max(1, min(SIGNATURE_COEFFICIENTS, width // 2 + 1)))
        return G[0] if one else G

    def readout_features(self, features: Any, signatures: Any = None) -> np.ndarray:
        """What the fitted readout regresses on: the slow features (N, m),
        with the signatures (N, q) appended when it reads them."""
        self._check_fitted()
        F = as_matrix(features, "features")
        if F.shape[1] != self.n_features_in_:
            raise ValueError(f"features have {F.shape[1]} columns, but this Localizer was fitted with {self.n_features_in_}")
        if not self.n_signature_:
            if signatures is not None:
                raise ValueError("this Localizer reads no appearance signature; pass signatures=None")
            return F
        if signatures is None:
            raise ValueError(f"this Localizer reads an appearance signature of {self.n_signature_} values beside the "
                             "slow features: pass signatures=localizer.signatures(images)")
        G = as_matrix(signatures, "signatures")
        check_same_length(F, G, "features", "signatures")
        if G.shape[1] != self.n_signature_:
            raise ValueError(f"signatures have {G.shape[1]} values, but this Localizer was fitted with "
                             f"{self.n_signature_}")
        return np.hstack([F, G])

    def _check_signature(self) -> str | None:
        if self.signature is not None and self.signature not in SIGNATURES:
            raise ValueError(f"signature must be one of {SIGNATURES} or None, got {self.signature!r}")
        return self.signature

    def _pooling(self) -> int:
        """The rotations averaged per image: the fitted value, else the
        parameter resolved."""
        if hasattr(self, "rotation_pooling_"):
            return self.rotation_pooling_
        return self._resolve_pooling()

    def _resolve_pooling(self) -> int:
        return pooling_for(self.readout, self.rotation_pooling, has_network=self.network is not None)

    def _check_params(self) -> tuple[int | None, float, int]:
        fitted = self.network is not None and self.network.is_fitted_
        n = check_n_outputs(self.n_outputs, self.network.n_outputs_ if fitted else None)
        ridge = check_nonneg_float(self.ridge, "ridge")
        degree = check_int(self.degree, "degree")
        ro = self.readout
        if not (isinstance(ro, dict) or ro in READOUTS):
            raise ValueError(f"readout must be 'auto', 'quadratic' or a readout spec dict, got {ro!r}")
        return n, ridge, degree

    # ------------------------------------------------------------ training
    def fit(self, images: Any, xy: Any) -> "Localizer":
        """Fits the regression on images (N, H, W[, C]) of a training run and
        their positions (N, 2) in metres (the network is not retrained).
        Returns ``self``."""
        Y = as_matrix(xy, "xy", n_cols=2)
        self.rotation_pooling_ = self._resolve_pooling()
        F = self.features(images)
        if F.ndim == 1:
            F = F[None]
        G = self.signatures(images) if self._check_signature() else None
        return self.fit_features(F, Y, signatures=None if G is None else G.reshape(len(F), -1))

    def partial_fit(self, images: Any, xy: Any = None, **kwargs: Any) -> "Localizer":
        """Adds a run to this fitted, updatable localizer (one with a
        ``readout_memory_``, :func:`sfanav.localization.updates.remember`):
        images (N, H, W[, C]) and their positions ``xy`` (N, 2) metres; the
        network's top stage is re-solved and the readout refitted
        (:class:`sfanav.localization.updates.LocalizerUpdater`, ``kwargs``
        its options). Returns ``self``; ValueError for a run that does not
        match or has no positions (``self`` is then unchanged).

        Examples
        --------
        >>> loc.partial_fit(week2_images, week2_xy)   # doctest: +SKIP
        """
        from .updates import LocalizerUpdater

        up = LocalizerUpdater(self, **kwargs).partial_fit(images, xy)
        new = up.solve() if up.n_pending_ else up.localizer_
        self.__dict__.update(new.__dict__)
        return self

    def fit_features(self, features: Any, xy: Any, *, signatures: Any = None,
                     augmented: tuple[Any, Any] | None = None, groups: Any = None) -> "Localizer":
        """Fits on precomputed features (N, m >= n_outputs), slowest first,
        and positions (N, 2) in metres: what :meth:`features` returns (rotation
        pooled as ``rotation_pooling`` says); with ``signature`` set also the
        images' :meth:`signatures` (N, q). Returns ``self``.

        ``augmented``: ``(features, signatures)`` of altered copies of the
        same N images (e.g. corrupted as a robot's camera may corrupt them,
        :class:`sfanav.data.corruptions.CorruptionModel`; signatures None
        without a signature), at the same positions: the readout is fitted
        on both, each copy next to its original (so that the blocked
        cross-validation of ``readout="auto"`` never holds out an image
        while training on its copy), and learns what of the features
        survives the alteration (docs/robustness.md). The training
        positions and metrics stay those of the N originals.

        ``groups`` (N,): the recording each sample comes from, when the
        training set is several recordings of the same places (in different
        light or seasons): ``readout="auto"`` then chooses its readout by
        holding out one recording at a time
        (:func:`sfanav.localization.select_auto_readout`); ignored by the
        other readouts."""
        self._check_params()
        if augmented is not None:
            return self._fit_augmented(features, xy, signatures, augmented, groups)
        return self._fit_samples(features, xy, signatures, groups, None)

    def _fit_samples(self, features: Any, xy: Any, signatures: Any, groups: Any, views: Any) -> "Localizer":
        """:meth:`fit_features` on samples as given; ``views``: the originals
        among them (None: all), for a readout that stores views."""
        n, ridge, degree = self._check_params()
        self.rotation_pooling_ = self._resolve_pooling()
        F = as_matrix(features, "features")
        Y = as_matrix(xy, "xy", n_cols=2)
        check_same_length(F, Y, "features", "xy")
        check_n_outputs(n, F.shape[1], what="the features have", unit="columns")
        kind = self._check_signature()
        if kind is not None and signatures is None:
            raise ValueError(f"this Localizer reads a {kind} signature beside the slow features: pass "
                             "signatures=localizer.signatures(images)")
        if kind is None and signatures is not None:
            raise ValueError("signatures given, but this Localizer reads none (signature=None)")
        G = None
        if kind is not None:
            G = as_matrix(signatures, "signatures")
            check_same_length(F, G, "features", "signatures")
            if isinstance(self.readout, str) and self.readout == "quadratic":
                raise ValueError("the quadratic readout reads no appearance signature: use readout='auto' or "
                                 "signature=None")
        q = 0 if G is None else G.shape[1]
        X = F if G is None else np.hstack([F, G])
        self.selection_ = None
        if isinstance(self.readout, dict):
            spec = dict(self.readout)
            if n is not None:
                spec["n_outputs"] = n
            if q:
                if spec.get("kind") not in ("gp-signature", "knn-signature"):
                    raise ValueError(f"a readout of kind {spec.get('kind')!r} reads no appearance signature: use "
                                     "{'kind': 'gp-signature'} or signature=None")
                spec["n_signature"] = q
            if spec.get("kind") == "knn-signature":
                spec["n_outputs"] = 0
                reg = make_readout(spec).fit(X, Y, views=views)
            else:
                reg = make_readout(spec).fit(X, Y)
        elif self.readout == "quadratic":
            spec = {"kind": "quadratic", "n_outputs": 8 if n is None else n, "ridge": float(ridge), "degree": degree}
            reg = QuadraticRegression(spec["n_outputs"], ridge, degree).fit(F, Y)
        else:
            sel = select_auto_readout(X, Y, n_outputs=n, n_signature=q, groups=groups, views=views)
            spec, reg, self.selection_ = sel.spec, sel.readout, sel
        self.regression_ = reg
        self.readout_spec_ = spec
        self.n_outputs_ = int(spec["n_outputs"]) if spec.get("n_outputs") is not None else F.shape[1]
        self.n_features_in_ = F.shape[1]
        self.n_signature_ = q
        self.training_positions_ = np.array(Y, dtype=np.float64)
        # the slowest features the readout reads (a signature-only readout: the 8 slowest)
        self.novelty_ = NoveltyReference().fit(F[:, : self.n_outputs_ or min(8, F.shape[1])]) if len(F) >= 2 else None
        rng = np.ptp(Y, axis=0)  # a straight training run has no range across it: use the other axis's
        rng = np.where(rng > 0, rng, max(float(rng.max()), 1.0))
        self.train_metrics_ = localization_metrics(_training_predictions(reg, X), Y, coordinate_range=rng)
        return self

    def _fit_augmented(self, features: Any, xy: Any, signatures: Any, augmented: Any, groups: Any) -> "Localizer":
        if not isinstance(augmented, (tuple, list)) or len(augmented) != 2:
            raise TypeError("augmented must be a tuple (features, signatures) of the altered copies")
        F, Y = as_matrix(features, "features"), as_matrix(xy, "xy", n_cols=2)
        Fa = as_matrix(augmented[0], "augmented features")
        if Fa.shape != F.shape:
            raise ValueError(f"augmented features must have the shape of the features {F.shape}, got {Fa.shape}")
        G = Ga = None
        if signatures is not None or augmented[1] is not None:
            if signatures is None or augmented[1] is None:
                raise ValueError("give signatures for both the images and their augmented copies, or for neither")
            G, Ga = as_matrix(signatures, "signatures"), as_matrix(augmented[1], "augmented signatures")
            if Ga.shape != G.shape:
                raise ValueError(f"augmented signatures must have the shape of the signatures {G.shape}, "
                                 f"got {Ga.shape}")
        check_same_length(F, Y, "features", "xy")

        def pairwise(a: np.ndarray, b: np.ndarray) -> np.ndarray:  # a0, b0, a1, b1, ...
            return np.stack([a, b], axis=1).reshape((-1,) + a.shape[1:])

        if groups is not None:
            groups = np.asarray(groups)
            if groups.shape != (len(F),):
                raise ValueError(f"groups must hold one label per image ({len(F)}), got shape {groups.shape}")
            groups = np.repeat(groups, 2)
        self._fit_samples(pairwise(F, Fa), pairwise(Y, Y), None if G is None else pairwise(G, Ga), groups,
                          np.arange(0, 2 * len(F), 2))
        self.training_positions_ = np.array(Y, dtype=np.float64)
        X = F if G is None else np.hstack([F, G])
        rng = np.ptp(Y, axis=0)
        rng = np.where(rng > 0, rng, max(float(rng.max()), 1.0))
        both = getattr(self.regression_, "training_predictions_", None)  # originals at the even places
        P = both[0::2] if both is not None and len(both) == 2 * len(F) else self.regression_.predict(X)
        self.train_metrics_ = localization_metrics(P, Y, coordinate_range=rng)
        self.n_augmented_ = len(F)
        return self

    def sibling(self, **overrides: Any) -> "Localizer":
        """A new, unfitted Localizer on the same network that sees images as
        this one does (rows, photometric normalisation, rotation pooling,
        signature) and reads them out as it does (readout, n_outputs), with
        ``overrides`` (constructor parameters) on top: e.g. the same
        features read out by another readout, or fitted to other positions.

        Examples
        --------
        >>> sup = loc.sibling().fit_features(F, xy_truth, signatures=G)   # doctest: +SKIP
        """
        params = {**self.get_params(), **overrides}
        return Localizer(**params)

    # ------------------------------------------------------------ inference
    def _check_fitted(self) -> Any:
        if not self.is_fitted_:
            raise NotFittedError("this Localizer is not fitted yet; call fit or fit_features first")
        return self.regression_

    def predict(self, images: Any, *, rotations: bool = False) -> np.ndarray:
        """Positions (N, 2) in metres of images (N, H, W[, C]).

        With ``rotations=True`` (a localizer without rotation pooling) the
        estimate is the mean over the simulated rotations of each image (as
        the thesis's Fig. 5.2b, 5.5b): K times the work, smoother estimates."""
        self._check_fitted()
        a = np.asarray(images)
        single = is_single_image(a, self.trained_network().input_shape[2])
        batch = a[None] if single else a
        G = self.signatures(batch) if self.n_signature_ else None
        out = self.predict_features(self.features(batch, rotations=rotations), signatures=G)
        return out[0] if single else out

    def predict_features(self, features: Any, *, signatures: Any = None) -> np.ndarray:
        """Positions (N, 2) in metres from precomputed features: (N, m), or
        (N, K, m) under K rotations, whose K estimates are averaged; with the
        images' :meth:`signatures` (N, q) if the localizer reads them."""
        reg = self._check_fitted()
        a = as_real_array(features, "features")
        if a.ndim == 3:
            check_finite(a.astype(np.float64, copy=False), "features")
            N, K, m = a.shape
            if m != self.n_features_in_:
                raise ValueError(f"features have {m} columns, but this Localizer was fitted with {self.n_features_in_}")
            G = None if signatures is None else np.repeat(as_matrix(signatures, "signatures"), K, axis=0)
            return reg.predict(self.readout_features(a.reshape(N * K, m), G)).reshape(N, K, -1).mean(axis=1)
        return reg.predict(self.readout_features(a, signatures))

    def novelty(self, images: Any) -> np.ndarray:
        """Novelty (N,) of images (N, H, W[, C]): how far each one's slowest
        features lie from the training run's, in units of the training
        features' typical nearest-neighbour distance (about 1 where the
        training drove, several where it did not;
        :class:`sfanav.localization.novelty.NoveltyReference`).
        :func:`sfanav.odometry.fuse` scales the filter's measurement noise by
        it. Raises ValueError for a model file written before the reference
        was stored (retrain it).

        >>> loc.novelty(test_images).round(1)        # doctest: +SKIP
        array([1.1, 0.9, ..., 6.8])
        """
        self._check_fitted()
        a = np.asarray(images)
        single = is_single_image(a, self.trained_network().input_shape[2])
        out = self.novelty_features(self.features(a[None] if single else a))
        return out[0] if single else out

    def predict_with_novelty(self, images: Any, *, rotations: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`predict` and :meth:`novelty` of a batch of images (N, H, W[, C])
        from one pass through the network: ``(xy (N, 2) m, novelty (N,))``
        (with ``rotations``, the novelty of the features averaged over the
        rotations). ValueError as :meth:`novelty` for a model without a
        novelty reference."""
        self._check_fitted()
        batch = np.asarray(images)
        if is_single_image(batch, self.trained_network().input_shape[2]):
            raise ValueError("predict_with_novelty takes a batch (N, H, W[, C]); use images[None] for one image")
        F = self.features(batch, rotations=rotations)
        G = self.signatures(batch) if self.n_signature_ else None
        xy = self.predict_features(F, signatures=G)
        return xy, self.novelty_features(F.mean(axis=1) if F.ndim == 3 else F)

    def novelty_features(self, features: Any) -> np.ndarray:
        """:meth:`novelty` from precomputed features (N, m), as :meth:`features` returns them."""
        self._check_fitted()
        if self.novelty_ is None:
            raise ValueError("this model holds no novelty reference (a model file written before 2026-12-06, or "
                             "fitted on one image): retrain it")
        F = as_matrix(features, "features")
        if F.shape[1] != self.n_features_in_:
            raise ValueError(f"features have {F.shape[1]} columns, but this Localizer was fitted with "
                             f"{self.n_features_in_}")
        return self.novelty_.score(F[:, : self.novelty_.reference_.shape[1]])

    def score(self, images: Any, xy: Any, *, rotations: bool = False) -> float:
        """Mean Euclidean distance (MED, metres) of the estimates for images
        from the true positions ``xy`` (N, 2): the thesis's accuracy figure.
        Lower is better (unlike scikit-learn's higher-is-better ``score``); see
        :meth:`evaluate` for all metrics."""
        return float(euclidean_errors(self.predict(images, rotations=rotations), xy).mean())

    def evaluate(self, images: Any, xy: Any, *, rotations: bool = False, coordinate_range: Any = None) -> dict[str, float]:
        """All metrics (:func:`sfanav.localization.localization_metrics`) of the
        estimates for images against ``xy`` (N, 2): MED, MAE per axis in
        metres and in % of the coordinate range, percentiles."""
        return localization_metrics(self.predict(images, rotations=rotations), xy, coordinate_range=coordinate_range)

    def evaluate_features(self, features: Any, xy: Any, *, coordinate_range: Any = None) -> dict[str, float]:
        """As :meth:`evaluate`, from precomputed features."""
        return localization_metrics(self.predict_features(features), xy, coordinate_range=coordinate_range)

    # ------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Saves the localizer with its network as one model file (pickle-free;
        kind ``"Localizer"``); read back with :func:`sfanav.load`."""
        reg = self._check_fitted()
        net_state = None
        if self.network is not None:
            # The network's own save() defines its state: write it and read it back.
            with tempfile.TemporaryDirectory(prefix="sfanav-") as tmp:
                tmp_path = Path(tmp) / "network.sfa"
                # an updatable localizer (with a readout memory) keeps the statistics its network's update needs
                self.network.save(tmp_path, include_statistics=self.readout_memory_ is not None)
                kind, net_state, _ = read_model(tmp_path)
        state = {
            "params": {"n_outputs": None if self.n_outputs is None else int(self.n_outputs),
                       "ridge": float(self.ridge), "degree": int(self.degree),
                       "rotation_pooling": (self.rotation_pooling if isinstance(self.rotation_pooling, str)
                                            or self.rotation_pooling is None else int(self.rotation_pooling))},
            "rotation_pooling": int(self.rotation_pooling_),
            "readout_param": dict(self.readout) if isinstance(self.readout, dict) else str(self.readout),
            "rows": None if self.rows is None else self.rows.to_dict(),
            **({} if self.photometric is None else {"photometric": self._check_photometric()}),
            **({} if self.photometric_lowpass() is None else {"lowpass": list(self.photometric_lowpass())}),
            "network": net_state,
            "readout": readout_state(self.readout_spec_, reg),
            # the thesis's readout also as version 1 had it, so older sfanav reads such files
            **({"regression": reg.get_state()} if self.readout_spec_["kind"] == "quadratic" else {}),
            "n_features_in": int(self.n_features_in_),
            **({"signature": {"kind": self.signature, "n_coefficients": SIGNATURE_COEFFICIENTS,
                              "n_values": int(self.n_signature_)}} if self.n_signature_ else {}),
            "train_metrics": dict(self.train_metrics_),
            "info": dict(self.info or {}),
            **({} if self.training_positions_ is None else {"training_positions": self.training_positions_}),
            # optional (older readers ignore it: they load the model, but cannot update it)
            **({} if self.readout_memory_ is None else {"readout_memory": self.readout_memory_.get_state()}),
            # optional (older readers ignore it; files without it have no novelty)
            **({} if self.novelty_ is None else {"novelty": self.novelty_.get_state()}),
        }
        # format version 2: a GP, kernel ridge or kNN readout (older readers cannot rebuild it)
        kind = self.readout_spec_["kind"]
        # format version 3: the GP readout (version-2 readers cannot rebuild it)
        version = {"quadratic": 1, "gp": 3}.get(kind, 2)
        # format version 4: rotation-pooled features (older readers would silently skip the pooling)
        if self.rotation_pooling_ > 1:
            version = 4
        # format version 5: an appearance signature beside the slow features
        if self.n_signature_:
            version = 5
        # format version 6: a photometric normalisation (older readers would silently skip it)
        if self.photometric is not None:
            version = 6
        # format version 7: the nearest training views by the signature (older readers cannot rebuild them)
        if kind == "knn-signature":
            version = 7
        # format version 8: the low-pass's widths other than 2 px (older readers would silently use 2 px)
        if self.photometric_lowpass() is not None:
            version = 8
        return save_model(path, "Localizer", state, version=version)

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "Localizer":
        try:
            net = None if state["network"] is None else Network.from_state(state["network"])
            rows = state.get("rows")
            params = dict(state["params"])
            params.setdefault("rotation_pooling", None)  # files before format 4: no pooling
            sig = state.get("signature")  # files before format 5: none
            loc = cls(net, rows=None if rows is None else ImageRows.from_dict(rows), **params,
                      signature=None if sig is None else sig["kind"], photometric=state.get("photometric"),
                      lowpass=None if state.get("lowpass") is None else tuple(state["lowpass"]))
            loc._check_photometric()
            loc.photometric_lowpass()
            loc.n_signature_ = 0 if sig is None else check_int(sig["n_values"], "signature n_values")
            if sig is not None and (loc._check_signature() is None
                                    or int(sig["n_coefficients"]) != SIGNATURE_COEFFICIENTS):
                raise ValueError(f"unsupported signature {sig!r}")
            loc.rotation_pooling_ = check_int(state.get("rotation_pooling", 1), "rotation_pooling")
            loc.readout = state.get("readout_param", "quadratic")
            if "readout" in state:  # model format 2 and later: any readout
                loc.regression_ = readout_from_state(state["readout"])
                loc.readout_spec_ = dict(state["readout"]["spec"])
            else:  # files written before: the thesis's quadratic regression
                loc.readout = "quadratic"
                loc.regression_ = QuadraticRegression.from_state(state["regression"])
                loc.readout_spec_ = {"kind": "quadratic", "n_outputs": loc.regression_.n_outputs_,
                                     "ridge": float(loc.ridge), "degree": int(loc.degree)}
            loc.n_outputs_ = int(loc.readout_spec_.get("n_outputs") or state["n_features_in"])
            loc.selection_ = None
            loc.n_features_in_ = int(state["n_features_in"])
            loc.train_metrics_ = dict(state.get("train_metrics") or {})
            loc.info = dict(state.get("info") or {})
            tp = state.get("training_positions")  # absent in files written before they were stored
            loc.training_positions_ = None if tp is None else as_matrix(tp, "training_positions", n_cols=2)
            nov = state.get("novelty")  # absent in files written before it was stored
            loc.novelty_ = None if nov is None else NoveltyReference.from_state(nov)
            if loc.novelty_ is not None and loc.novelty_.reference_.shape[1] > loc.n_features_in_:
                raise ValueError(f"the novelty reference has {loc.novelty_.reference_.shape[1]} columns, the "
                                 f"features {loc.n_features_in_}")
            if state.get("readout_memory") is not None:  # absent unless the localizer was made updatable
                from .updates import ReadoutMemory

                loc.readout_memory_ = ReadoutMemory.from_state(state["readout_memory"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"invalid Localizer model state: {exc}") from None
        if net is not None and net.is_fitted_ and loc.n_features_in_ != net.n_outputs_:
            raise ValueError(
                f"invalid Localizer model state: the regression expects {loc.n_features_in_} features, "
                f"the network has {net.n_outputs_} outputs"
            )
        # One probe prediction: the readout's arrays must fit each other and
        # the feature count, and give one finite position per image.
        try:
            probe = loc.predict_features(np.zeros((1, loc.n_features_in_)), signatures=(
                np.zeros((1, loc.n_signature_)) if loc.n_signature_ else None))
        except ValueError as exc:
            raise ValueError(f"invalid Localizer model state: the readout does not fit its features ({exc})") from None
        if probe.shape != (1, 2) or not np.isfinite(probe).all():
            raise ValueError(f"invalid Localizer model state: the readout gives {probe.shape[1:]} values per image "
                             "where one finite (x, y) position is due")
        return loc


register_loader("Localizer", Localizer.from_state)

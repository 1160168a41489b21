#!/usr/bin/env python3
"""What each candidate means against camera corruptions costs and buys (docs/robustness.md): the sfanav
default's network trained on a clean exploration run, tested on the clean test run and on corrupted copies
of it (the corruption applied at the images' own resolution), in four gardens; MED per corruption and its
ratio to the candidate's clean MED, and the clean MED against robustness "none" (the default before).

Candidates (all the sfanav default's network, rows, pooling, signature and readout):

* none: nothing (the default before the corruption study);
* photometric: the log-contrast normalisation alone;
* row-gain: every row and channel divided by its mean (a per-row normalisation, which also removes
  vignetting) instead;
* channel-gain: every channel divided by its image mean (exposure and white balance without the log);
* readout: the readout fitted on a corrupted copy of the run as well (CAMERA), no normalisation;
* light: photometric + readout (log-contrast, as measured; the level "light" now uses lowpass-log-contrast);
* full: light + the network's invariance partners (CAMERA, weight 1);
* full-0.5: the same at weight 0.5;
* full-0.25: the same at weight 0.25;
* full-24: full with 24 top outputs, all read out (does capacity buy back the precision the invariance costs?);
* jpeg-invariance: light + invariance partners that are JPEG round trips only (quality 50..95);
* lowpass-2-flat-0.25: the sfanav default, robustness "standard" (the library's lowpass-log-contrast is
  lowpass-2-flat here: equal to 1e-4); lowpass-2-flat-1: robustness "full"; lowpass-2-flat: "light";
* lowpass-S: a Gaussian low-pass of sigma S px (at the network's resolution, wrapping around the
  panorama) before the log-contrast normalisation, with light's readout augmentation (JPEG, noise,
  defocus and dead pixels live in the fine structure the low-pass takes away);
* lowpass-S-0.25: the same with standard's invariance partners (weight 0.25);
* lowpass-S-flat(-0.25): the same, then a quadratic profile over the rows of the rows' means removed
  per channel (in the log domain: a vignetting is a smooth offset per row); -0.5, -1: invariance weights;
* lowpass-2-flat-o2-0.25: with 2 grey levels added before the log instead of 8 (gamma is exact in the
  log domain without the offset; the low-pass already damps the dark pixels' noise);
* gamma-W: the default's normalisation (lowpass-2-flat) with gamma 0.6..1.6 added to the corruptions of
  the invariance partners and the readout's copies (CAMERA_GAMMA), invariance weight W (0.25, 0.5);
  gamma-lowpass-3-flat-0.25: the same with a 3 px low-pass (lowpass-3-flat-0.25 without gamma);
* twice-0.25: the default with its network trained on the run twice over (two copies one after the other),
  each copy with its own draw of partners: two partners per image, the readout on the run once;
* wideN-0.25, wideN: the default (standard) and light with N top outputs instead of 12, all read out
  (whether the features the partners' draw decides about survive in a wider top layer);
* NAME@S: candidate NAME trained with fit_localizer(seed=S), the draw of the partners' and the readout copies'
  corruptions (the spread over S is what the draw alone does);
* stratified-0.25, dealt-0.25: the default with the partners' corruption families dealt in turn along the run
  (image i gets family (i + seed) mod 7) instead of drawn uniformly; the two differ only in the stream their
  strengths are drawn from (StratifiedModel, DealtModel);
* clipQQ-0.25, clipQQ-gamma-0.25: every channel clipped at its QQ-th percentile before the default's
  normalisation (a clipped overexposure is then a gain while less than 1 - QQ % saturates), with gamma
  partners; eq-S-flat-0.25, eqlog-S-flat-0.25 (-gamma): a coarse histogram equalisation per channel (16
  quantile knots) after an S px low-pass, with or without the log, then the flat field;
* --matched C1,C2: the candidate trained on the exploration run with corruption C and tested on the test run
  with C (the model that has seen the camera);
* lowpass-2-flat-0.25-clean-readout: the default with its readout fitted on the clean run only (what the
  corrupted copies cost the readout's precision; measured first on the 6.2.1 scenes);
* logfirst-2-oK-0.25: the logarithm (offset K grey levels) before the 2 px low-pass, then the flat field and
  contrast, with standard's partners: the low-pass before the log does not commute with a gamma, after it
  the gamma is a scale of the log the contrast step removes (measured with --extra, which adds gamma 0.7
  and exposure 0.6).

    for p in suite-inner suite-control suite-dense-trees; do sfanav simulate --preset $p --seed 1 --out runs/cand/$p; done
    sfanav simulate --preset demo --out runs/cand/demo
    PYTHONPATH=python python3 scripts/investigations/robustness_candidates.py runs/cand \\
        --json docs/results/investigations/robustness-candidates.json
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np
from _seeds import seed_groups

import sfanav.localization.localizer as localizer_module
from sfanav.data import Dataset, Preprocessing, load_run
from sfanav.data.corruptions import CAMERA, CorruptionModel, corrupt
from sfanav.data.preprocessing import Preprocessor
from sfanav.localization.error_metrics import localization_metrics
from sfanav.localization.recipe import default_network, recipe_for
from sfanav.localization.training import fit_localizer
from sfanav.sfa import Rotation

GARDENS = {"suite-inner": ("train-grid", "test-walk"), "demo": ("train", "test"),
           "suite-control": ("train-grid", "test-walk"), "suite-dense-trees": ("train-grid", "test-walk"),
           "6.2.1-static": ("train", "test"), "6.2.1-dynamic": ("train", "test"), "6.2.1-light": ("train", "test")}
"""The gardens (folder names under ROOT); the 6.2.1 scenes (from 2026-12-06: ``thesis-6.2.1-static`` /
``-dynamic`` at seed 0, omnidirectional images) are unwarped to the network's 350x40 and corrupted at that
size. The default --gardens are the first four."""
DEFAULT_GARDENS = ("suite-inner", "demo", "suite-control", "suite-dense-trees")
CORRUPTIONS = ["jpeg-90", "jpeg-50", "noise-10", "defocus-1", "defocus-2", "motion-blur", "exposure-1.5",
               "gamma-1.4", "white-balance", "vignetting", "dead-pixels"]
EXTRA_CORRUPTIONS = ["gamma-0.7", "exposure-0.6"]
"""Measured from 2026-12-06 (--extra): the gamma below 1 and the underexposure the first runs did not have."""
JPEG_ONLY = CorruptionModel({"jpeg": {"kind": "jpeg", "quality": (50, 95)}})
GAMMA_CONTRAST = 0.57
"""canonical_gamma's log contrast (standard deviation of log(I + offset) about the channels' means): near a
flawless garden panorama's own, so that most images change little."""
CAMERA_GAMMA = CorruptionModel({**CAMERA.families, "gamma": {"kind": "gamma", "gamma": (0.6, 1.6)}})
"""CAMERA with gamma 0.6..1.6 as an eighth family (what the normalisation leaves of a gamma)."""


class StratifiedModel(CorruptionModel):
    """CAMERA with the families dealt in turn along the run (image i gets family (i + seed) mod F, its parameters
    drawn as before) instead of one uniformly random family per image: every family equally often and evenly
    spread over the run, whatever the seed (does the partners' draw make the clean precision a lottery?)."""

    skip_uniform = False
    """Draw (and ignore) the uniform family first, as CAMERA does, so that the strengths are CAMERA's."""

    def draw(self, n, *, seed=0, start=0, dealt=False):
        names = list(self.families)
        out = []
        for i in range(start, start + n):
            rng = np.random.default_rng([seed, i, 17])
            if self.skip_uniform:
                rng.integers(len(names))
            out.append(self._draw(names[(i + seed) % len(names)], rng))
        return out


class DealtModel(StratifiedModel):
    """StratifiedModel's families with the strengths CAMERA draws for the image (the same stream, after the
    uniform family draw it ignores): the two differ only in their strength draws (measured as dealt-0.25)."""

    skip_uniform = True


CAMERA_STRATIFIED = StratifiedModel(CAMERA.families)
CAMERA_DEALT = DealtModel(CAMERA.families)


def row_gain(images):
    a = np.asarray(images, np.float32)
    return a / np.maximum(a.mean(axis=2, keepdims=True), 8.0) * 100.0


def channel_gain(images):
    a = np.asarray(images, np.float32)
    return a / np.maximum(a.mean(axis=(1, 2), keepdims=True), 4.0) * 100.0


def quantile_clip(images, q):
    """Every image's channels clipped at their own q-quantile (q in 0..1): a clipped overexposure (``min(g I,
    255)``) is then exactly the gain ``g`` while less than 1 - q of a channel saturates, and the clip commutes
    with a gamma and a white balance (a quantile commutes with any increasing map of one channel)."""
    b, single = _batch(images)
    top = np.quantile(b, q, axis=(1, 2), keepdims=True).astype(np.float32)
    out = np.minimum(b, top)
    return out[0] if single else out


def quantile_equalize(images, knots=16, spacing=1.0):
    """Every image's channels mapped through their own quantiles onto a uniform 0..255 range, piecewise
    linearly between ``knots`` + 1 quantile levels (a coarse histogram equalisation): invariant to any
    increasing map of a channel (gain, gamma, white balance, clipping but for the clipped pixels) as far as it
    is linear between knots; knots closer than ``spacing`` grey levels are pushed apart so that noise in a flat
    region (the sky) is not stretched over a wide range."""
    b, single = _batch(images)
    b4 = b if b.ndim == 4 else b[..., None]
    levels = np.linspace(0.0, 1.0, knots + 1)
    out = np.empty(b4.shape, np.float32)
    for i in range(len(b4)):
        for c in range(b4.shape[-1]):
            v = b4[i, ..., c]
            x = np.quantile(v, levels)
            for j in range(1, len(x)):
                x[j] = max(x[j], x[j - 1] + spacing)
            out[i, ..., c] = np.interp(v, x, levels * 255.0)
    out = out if b.ndim == 4 else out[..., 0]
    return out[0] if single else out


def canonical_gamma(images, offset=2.0, contrast=GAMMA_CONTRAST):
    """Every image's gamma made canonical before the low-pass: L = log(I + offset) centred per channel is scaled
    to the standard deviation ``contrast`` and mapped back to intensities, I' = exp(mean_k + (L - mean_k) s) -
    offset (the image's own per-channel means kept: a gain commutes with the low-pass). A gamma ``255 (I /
    255)^g`` is a scale of L (exactly for offset 0), so I' no longer depends on it, and the low-pass that follows
    sees the same intensities whatever the camera's gamma; a flawless image changes only by its own log
    contrast's distance from ``contrast``."""
    b, single = _batch(images)
    b4 = b if b.ndim == 4 else b[..., None]
    out = np.empty(b4.shape, np.float32)
    for i in range(len(b4)):
        L = np.log(np.maximum(b4[i], 0.0) + np.float32(offset))
        mu = L.mean(axis=(0, 1), keepdims=True)
        sd = float((L - mu).std())
        k = np.float32(contrast / sd) if sd > 1e-6 else np.float32(1.0)
        out[i] = np.exp(mu + (L - mu) * k) - np.float32(offset)
    out = out if b.ndim == 4 else out[..., 0]
    return out[0] if single else out


QUANTILES = (0.05, 0.35)
FLAT = True
"""RunGamma's spread "quantile": between these quantiles of an image's log intensities."""


class RunGamma:
    """A camera's gamma estimated over a run rather than per image: the first call (the training run) records the
    median over its images of the standard deviation of log(I + offset) about each image's channel means, and
    returns the images unchanged; every later call (a test run, all of its images at once, as a robot's stream
    would accumulate them) maps its images through canonical_gamma's power with one factor for the whole run, the
    training median over the run's own median, so that a run whose camera applies a gamma g is brought back by
    1 / g and a run of the same camera is left (nearly) as it is. The network and readout are the default's, trained
    on the unchanged run: paired with the default at the same seed, only the test images differ."""

    def __init__(self, offset=2.0, spread="std"):
        self.offset, self.reference, self.spread = float(offset), None, spread

    def _spread(self, b4):
        """The run's median over images of their log spread: ``"std"`` the standard deviation about the channels'
        means, ``"quantile"`` the distance from the 10th to the 50th percentile of the log intensities (a gamma
        scales it exactly; a gain and the clipping of up to half the pixels, an overexposure, leave it)."""
        L = np.log(np.maximum(b4, 0.0) + np.float32(self.offset))
        mu = L.mean(axis=(1, 2), keepdims=True)
        if self.spread == "quantile":  # per channel, after the rows' quadratic profile (a vignetting) is removed
            h = L.shape[1]
            t = np.linspace(-1.0, 1.0, h)
            V = np.stack([np.ones(h), t, t * t], axis=1)
            F = L - np.einsum("ij,nj...->ni...", V @ np.linalg.pinv(V), L.mean(axis=2))[:, :, None] if FLAT else L
            F = F.mean(axis=-1).reshape(len(F), -1)  # the channels' mean log: a gamma scales it, a white balance moves it
            q = np.quantile(F, QUANTILES, axis=1)
            return float(np.median(q[1] - q[0])), L, mu
        if self.spread == "flat-std":  # per channel, after the rows' quadratic profile (a vignetting) is removed
            h = L.shape[1]
            t = np.linspace(-1.0, 1.0, h)
            V = np.stack([np.ones(h), t, t * t], axis=1)
            F = L - np.einsum("ij,nj...->ni...", V @ np.linalg.pinv(V), L.mean(axis=2))[:, :, None]
            return float(np.median(F.reshape(len(F), -1).std(axis=1))), L, mu
        return float(np.median((L - mu).reshape(len(L), -1).std(axis=1))), L, mu

    def __call__(self, images):
        b, single = _batch(images)
        b4 = b if b.ndim == 4 else b[..., None]
        spread, L, mu = self._spread(b4)
        if self.reference is None:
            self.reference = spread
            return images
        k = np.float32(self.reference / spread)
        # not clipped at 255: the power's gain would saturate bright pixels (the normalisation takes any level)
        out = np.maximum(np.exp(mu + (L - mu) * k) - np.float32(self.offset), 0.0).astype(np.float32)
        out = out if b.ndim == 4 else out[..., 0]
        return out[0] if single else out


class StreamGamma:
    """The library's camera gamma (sfanav.data.camera_gamma.CameraGamma, what ``sfanav localize --camera-gamma``
    and the streaming localizer run): a test run, in its order, localized once, its images' gamma estimated
    against the training views where they are placed (the model's stored reference), and localized again where a
    factor applies (predict_corrected), with a fresh tracker per run."""

    def __init__(self, loc, pixels=False):
        self.loc, self.pixels = loc, pixels

    def predict(self, X, native=None, conform=None):
        """``pixels`` (the library's default since 2026-12-08: the guard, the factors on the camera's ``native``
        images before ``conform``, the warm-up batch corrected); else the tracker as measured on 2026-12-07 (the
        factors on the conformed images; the guard and the warm-up batch now in the library apply to both)."""
        from sfanav.data.camera_gamma import CameraGamma, predict_corrected

        kw = {"source": native, "conform": conform} if self.pixels and native is not None else {}
        return predict_corrected(self.loc, CameraGamma.for_localizer(self.loc), X, **kw)


def _batch(images):
    """(float32 batch (N, H, W[, C]), whether ``images`` was a single image)."""
    a = np.asarray(images, np.float32)
    single = a.ndim in (2, 3) and not (a.ndim == 3 and a.shape[-1] > 4)
    return (a[None] if single else a), single


def _lowpass(b, sigma):
    """A Gaussian low-pass of ``sigma`` px of every image of a batch (wrapping around the panorama's seam)."""
    from scipy.ndimage import gaussian_filter

    sig = (sigma, sigma, 0.0)[:b.ndim - 1]
    modes = ("nearest", "wrap", "nearest")[:b.ndim - 1]
    return np.stack([gaussian_filter(im, sig, mode=modes) for im in b])


def _flat_contrast(v):
    """A batch of (log) images minus the quadratic profile over the rows (per channel) of the rows' means, scaled
    to the normalisation's contrast (40 per standard deviation)."""
    h = v.shape[1]
    t = np.linspace(-1.0, 1.0, h)
    V = np.stack([np.ones(h), t, t * t], axis=1)
    P = V @ np.linalg.pinv(V)  # projector onto the quadratic profiles
    v = v - np.einsum("ij,nj...->ni...", P, v.mean(axis=2)).astype(np.float32)[:, :, None]
    sd = v.reshape(len(v), -1).std(axis=1).reshape((-1,) + (1,) * (v.ndim - 1))
    return (v * (40.0 / np.maximum(sd, 1e-6))).astype(np.float32)


def _lowpass_normalize(images, kind, lowpass=None):
    """log-contrast after a Gaussian low-pass: kind 'lowpass-S' (S in px); a prefix 'clipQQ-' first clips every
    channel at its QQ-th percentile (quantile_clip); 'eq[log]-S-flat': low-pass S px, equalise, [log,] flat field."""
    from sfanav.data.photometric import PHOTOMETRIC, log_contrast, normalize
    if kind is not None and kind.startswith("eq"):
        parts = kind.split("-")
        b, single = _batch(images)
        b = quantile_equalize(_lowpass(b, float(parts[1])))
        out = _flat_contrast(np.log(b + 8.0) if parts[0] == "eqlog" else b)
        return out[0] if single else out
    if kind is not None and kind.startswith("gammafix"):  # gammafixO-REST: canonical_gamma(offset O), then REST
        head, kind = kind.split("-", 1)
        images = canonical_gamma(images, offset=float(head[8:]))
        if kind == "default":
            return normalize(images, "lowpass-log-contrast", lowpass=lowpass)
    if kind is not None and kind.startswith("clip"):
        head, kind = kind.split("-", 1)
        images = quantile_clip(images, float(head[4:]) / 100.0)
        if kind == "default":
            return normalize(images, "lowpass-log-contrast", lowpass=lowpass)
    if kind is None or kind in PHOTOMETRIC or not kind.startswith(("lowpass-", "logfirst-")):  # the library's own
        return normalize(images, kind, lowpass=lowpass)
    parts = kind.split("-")
    sigma = float(parts[1])
    log_first = parts[0] == "logfirst"
    flat = "flat" in parts or log_first
    offset = next((float(p[1:]) for p in parts if p.startswith("o")), 8.0)
    b, single = _batch(images)
    if log_first:  # the logarithm before the low-pass: a gamma is then a scale the contrast step removes
        b = np.log(np.maximum(b, 0.0) + np.float32(offset))
    out = _lowpass(b, sigma)
    if flat:  # log, minus a quadratic profile over the rows (per channel) of the rows' means, then the contrast
        out = _flat_contrast(out if log_first else np.log(np.maximum(out, 0.0) + offset))
    else:
        out = log_contrast(out)
    return out[0] if single else out


localizer_module.photometric_normalize = _lowpass_normalize
LOWPASS = ("0.7", "1", "1.5", "2", "1-flat", "2-flat", "2-flat-o2", "3-flat")
LOGFIRST = ("2-o2", "2-o8", "2-o16", "2-o32")
CLIP = ("80", "90", "95")
GAMMAFIX = ("1", "2", "4", "8")
localizer_module.PHOTOMETRIC = (*localizer_module.PHOTOMETRIC, *(f"lowpass-{s}" for s in LOWPASS),
                                *(f"logfirst-{s}" for s in LOGFIRST),
                                *(f"clip{q}-{k}" for q in CLIP for k in ("default", "lowpass-1-flat")),
                                *(f"{e}-{s}-flat" for e in ("eq", "eqlog") for s in ("1", "2", "3")),
                                *(f"gammafix{o}-default" for o in GAMMAFIX))

CANDIDATES = {
    "none": ({"robustness": "none"}, None),
    "photometric": ({"robustness": "none", "photometric": "log-contrast"}, None),
    "row-gain": ({"robustness": "none"}, row_gain),
    "channel-gain": ({"robustness": "none"}, channel_gain),
    "readout": ({"robustness": "none", "readout_augmentation": CAMERA}, None),
    # measured with the first photometric normalisation (log-contrast), pinned so that a rerun is the same
    "light": ({"robustness": "light", "photometric": "log-contrast"}, None),
    "full": ({"robustness": "full", "photometric": "log-contrast"}, None),
    "full-0.5": ({"robustness": "full", "invariance_weight": 0.5, "photometric": "log-contrast"}, None),
    "full-0.25": ({"robustness": "full", "invariance_weight": 0.25, "photometric": "log-contrast"}, None),
    "full-24": ({"robustness": "full", "n_outputs": 24, "network": {"out": 24}, "photometric": "log-contrast"}, None),
    "jpeg-invariance": ({"robustness": "light", "invariance": JPEG_ONLY, "photometric": "log-contrast"}, None),
    **{f"lowpass-{s}": ({"robustness": "light", "photometric": f"lowpass-{s}"}, None) for s in LOWPASS},
    **{f"lowpass-{s}-0.25": ({"robustness": "standard", "photometric": f"lowpass-{s}"}, None)
       for s in LOWPASS},
    **{f"logfirst-{s}-0.25": ({"robustness": "standard", "photometric": f"logfirst-{s}"}, None) for s in LOGFIRST},
    "lowpass-2-flat-0.5": ({"robustness": "full", "invariance_weight": 0.5, "photometric": "lowpass-2-flat"}, None),
    **{f"lowpass-2-flat-{w}": ({"robustness": "full", "invariance_weight": w, "photometric": "lowpass-2-flat"}, None)
       for w in (0.1, 0.15)},
    "lowpass-2-flat-1": ({"robustness": "full", "photometric": "lowpass-2-flat"}, None),
    **{f"gamma-{w}": ({"robustness": "full", "invariance_weight": w, "photometric": "lowpass-2-flat",
                      "invariance": CAMERA_GAMMA, "readout_augmentation": CAMERA_GAMMA}, None)
       for w in (0.25, 0.5)},
    "lowpass-2-flat-0.25-clean-readout": ({"robustness": "standard", "photometric": "lowpass-2-flat",
                                           "readout_augmentation": None}, None),
    "gamma-lowpass-3-flat-0.25": ({"robustness": "standard", "photometric": "lowpass-3-flat",
                                   "invariance": CAMERA_GAMMA, "readout_augmentation": CAMERA_GAMMA}, None),
    **{f"clip{q}-0.25": ({"robustness": "standard", "photometric": f"clip{q}-default"}, None) for q in CLIP},
    **{f"clip{q}-gamma-0.25": ({"robustness": "standard", "photometric": f"clip{q}-default",
                                "invariance": CAMERA_GAMMA, "readout_augmentation": CAMERA_GAMMA}, None)
       for q in CLIP},
    **{f"clip{q}-gamma-lowpass-1-flat-0.25": ({"robustness": "standard", "photometric": f"clip{q}-lowpass-1-flat",
                                               "invariance": CAMERA_GAMMA, "readout_augmentation": CAMERA_GAMMA},
                                              None) for q in CLIP},
    **{f"wide{n}-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat", "n_outputs": n,
                          "network": {"out": n}}, None) for n in (16, 24)},
    **{f"wide{n}": ({"robustness": "light", "photometric": "lowpass-2-flat", "n_outputs": n,
                     "network": {"out": n}}, None) for n in (16, 24)},
    "twice-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat", "twice": True}, None),
    "dealt-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat", "invariance": CAMERA_DEALT}, None),
    "stratified-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat", "invariance": CAMERA_STRATIFIED},
                        None),
    "rungamma-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat"}, "rungamma"),
    "rungammaq-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat"}, "rungammaq"),
    "rungammaf-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat"}, "rungammaf"),
    "camgamma-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat"}, "camgamma"),
    "camgammapx-0.25": ({"robustness": "standard", "photometric": "lowpass-2-flat"}, "camgammapx"),
    "standard": ({"robustness": "standard"}, None),
    "standard-camgamma": ({"robustness": "standard"}, "camgamma"),
    **{f"gammafix{o}-0.25": ({"robustness": "standard", "photometric": f"gammafix{o}-default"}, None)
       for o in GAMMAFIX},
    **{f"{e}-{s}-flat-0.25": ({"robustness": "standard", "photometric": f"{e}-{s}-flat"}, None)
       for e in ("eq", "eqlog") for s in ("1", "2", "3")},
    **{f"{e}-{s}-flat-gamma-0.25": ({"robustness": "standard", "photometric": f"{e}-{s}-flat",
                                     "invariance": CAMERA_GAMMA, "readout_augmentation": CAMERA_GAMMA}, None)
       for e in ("eq", "eqlog") for s in ("1", "2", "3")},
}


class _Normalised:
    def __init__(self, f, loc):
        self.f, self.loc = f, loc

    def predict(self, X):
        return self.loc.predict(self.f(X))


def train(name, X, xy, elev):
    """A candidate trained on images X at xy; ``NAME@S``: the candidate with fit_localizer(seed=S) (the draw of
    the invariance partners' and the readout copies' corruptions)."""
    name, _, seed = name.partition("@")
    opts, pre = CANDIDATES[name]
    opts = dict(opts)
    if seed:
        opts["seed"] = int(seed)
    if opts.pop("twice", False):  # the network sees the run twice, each copy with its own partners
        return _twice(opts, X, xy, elev)
    kw = recipe_for(robustness=opts.pop("robustness")).fit_kwargs(elev, X.shape[1])
    net = default_network(**opts.pop("network", {}))
    kw.update(opts)
    if kw.get("photometric") != "lowpass-log-contrast":  # the script's own kinds set their low-pass in their name
        kw.pop("lowpass", None)
    if pre in ("camgamma", "camgammapx"):
        return StreamGamma(fit_localizer(net, X, xy, rotation=Rotation(5, 1.0), progress=False, **kw),
                           pixels=pre == "camgammapx")
    if pre in ("rungamma", "rungammaq", "rungammaf"):
        pre = RunGamma(spread={"rungamma": "std", "rungammaq": "quantile", "rungammaf": "flat-std"}[pre])
    if pre is None:
        return fit_localizer(net, X, xy, rotation=Rotation(5, 1.0), progress=False, **kw)
    return _Normalised(pre, fit_localizer(net, pre(X), xy, rotation=Rotation(5, 1.0), progress=False, **kw))


def _twice(opts, X, xy, elev):
    """The candidate with its network trained on the run twice over, one copy after the other, each copy with its
    own draw of invariance partners (seed and seed + 7919); the readout on the run once."""
    import sfanav.localization.training as training

    kw = recipe_for(robustness=opts.pop("robustness")).fit_kwargs(elev, X.shape[1])
    kw.update(opts)
    if kw.get("photometric") != "lowpass-log-contrast":
        kw.pop("lowpass", None)
    net = default_network()
    original, fit = training.invariance_partners, net.fit

    def partners(images, model, network_input, **k):
        a = original(images, model, network_input, **k)
        b = original(images, model, network_input, **{**k, "seed": k.get("seed", 0) + 7919})
        return np.arange(2 * len(images)), np.concatenate([a[1], b[1]]), np.concatenate([a[2], b[2]])

    net.fit = lambda images, rotation, **k: fit(np.concatenate([images, images]), rotation, **k)
    training.invariance_partners = partners
    try:
        return fit_localizer(net, X, xy, rotation=Rotation(5, 1.0), progress=False, **kw)
    finally:
        training.invariance_partners = original


def markdown(out):
    """The candidates' table of docs/robustness.md from the JSON (no training)."""
    gardens = [g for g in GARDENS if any(k.startswith(g + "|") for k in out)]
    names = list(dict.fromkeys(k.split("|")[1] for k in out if "|" in k))
    head = " / ".join(gardens)
    lines = [f"| candidate | clean MED (m): {head} | clean / none (geometric mean) | worst ratio to own clean: {head} "
             f"| JPEG 90 ratio: {head} |", "|---|---|---|---|---|"]
    for n in names:
        cells = [out.get(f"{g}|{n}", {}).get("MED (m)") for g in gardens]
        base = [out.get(f"{g}|none", {}).get("MED (m)") for g in gardens]
        if any(c is None for c in cells):
            continue
        cost = np.exp(np.mean([np.log(c["clean"] / b["clean"]) for c, b in zip(cells, base)]))
        worst = [max(v for k, v in c.items() if k != "clean") / c["clean"] for c in cells]
        lines.append(f"| {n} | " + " / ".join(f"{c['clean']:.3f}" for c in cells) + f" | {cost:.2f} | "
                     + " / ".join(f"{w:.1f}" for w in worst) + " | "
                     + " / ".join(f"{c['jpeg-90'] / c['clean']:.2f}" for c in cells) + " |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("root", help="folder with one simulated dataset per garden (named as the preset)")
    ap.add_argument("--candidates", default=",".join(CANDIDATES))
    ap.add_argument("--gardens", default=",".join(DEFAULT_GARDENS))
    ap.add_argument("--json")
    ap.add_argument("--markdown", action="store_true", help="print the docs' table from --json and stop")
    ap.add_argument("--summarize", action="store_true", help="recompute the seed spread of --json and stop")
    ap.add_argument("--extra", action="store_true", help="also the corruptions of EXTRA_CORRUPTIONS")
    ap.add_argument("--matched", help="comma-separated corruptions: train each candidate on the corrupted "
                    "exploration run and test on the test run with the same corruption (the model that has seen "
                    "exactly this camera: what no invariance can beat by much), instead of the clean-trained table")
    a = ap.parse_args()
    out = json.loads(Path(a.json).read_text()) if a.json and Path(a.json).exists() else {}
    if a.markdown:
        print(markdown(out))
        return
    if a.summarize:
        out["seeds"] = seed_spread(out)
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")
        print(json.dumps(out["seeds"], indent=1))
        return
    prep = Preprocessing.for_network(default_network())
    for g in a.gardens.split(","):
        ds = Dataset(Path(a.root) / g)
        cam = ds.metadata["camera"]
        native = (Preprocessing(prep.width, prep.height, False) if cam.get("type") == "omni"
                  else Preprocessing(int(cam["width"]), int(cam["height"]), False))
        tr, te = GARDENS[g]
        X0, xy = load_run(ds.select(run=tr), native, log=lambda m: None)
        T0, xyt = load_run(ds.select(run=te), native, log=lambda m: None)
        conform = Preprocessor(prep, log=lambda *m, **k: None)
        X = conform(X0)
        natives = {"clean": T0, **{c: corrupt(T0, c, seed=1) for c in CORRUPTIONS + (EXTRA_CORRUPTIONS if a.extra
                                                                                   else [])}}
        tests = {c: conform(N) for c, N in natives.items()}
        elev = tuple(cam["elevation_deg"])
        if a.matched:
            for name in a.candidates.split(","):
                key = f"{g}|{name}|matched"
                med = dict(out.get(key, {}).get("MED (m)", {}))
                for c in ["clean"] + a.matched.split(","):
                    Xc = X if c == "clean" else conform(corrupt(X0, c, seed=2))
                    model = train(name, Xc, xy, elev)
                    med[c] = localization_metrics(model.predict(tests[c]), xyt)["med"]
                    print(f"{g:18s} {name:16s} trained and tested on {c}: {med[c]:.3f} m "
                          f"(x{med[c] / med['clean']:.2f} clean)", flush=True)
                    out[key] = {"MED (m)": med}
                    if a.json:
                        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")
            continue
        for name in a.candidates.split(","):
            t0 = time.perf_counter()
            model = train(name, X, xy, elev)
            secs = time.perf_counter() - t0
            med = {c: localization_metrics(model.predict(T, natives[c], conform) if isinstance(model, StreamGamma)
                                           else model.predict(T), xyt)["med"] for c, T in tests.items()}
            out[f"{g}|{name}"] = {"MED (m)": med, "training (s)": secs}
            if isinstance(model, StreamGamma):  # the same model without the correction: the paired baseline
                plain = {c: localization_metrics(model.loc.predict(T), xyt)["med"] for c, T in tests.items()}
                out[f"{g}|{name.replace('-camgamma', '').replace('camgammapx', 'lowpass-2-flat').replace('camgamma', 'lowpass-2-flat')}"] = {
                    "MED (m)": plain, "training (s)": secs}
            ratios = {c: v / med["clean"] for c, v in med.items() if c != "clean"}
            print(f"{g:18s} {name:16s} clean {med['clean']:.3f} worst x{max(ratios.values()):.2f} "
                  f"train {secs:.0f} s | " + " ".join(f"{c} {r:.2f}" for c, r in ratios.items()), flush=True)
            if a.json:
                Path(a.json).write_text(json.dumps(out, indent=1) + "\n")
    summary = {}
    for name in dict.fromkeys(k.split("|")[1] for k in out if k != "summary"):
        cells = [out[f"{g}|{name}"]["MED (m)"] for g in a.gardens.split(",") if f"{g}|{name}" in out]
        base = [out[f"{g}|none"]["MED (m)"]["clean"] for g in a.gardens.split(",") if f"{g}|none" in out]
        if not cells:
            continue
        worst = max(max(v for c, v in m.items() if c != "clean") / m["clean"] for m in cells)
        cost = float(np.exp(np.mean(np.log([m["clean"] / b for m, b in zip(cells, base)])))) if base else None
        summary[name] = {"worst ratio to own clean": worst, "clean / none (geometric mean)": cost}
        print(f"{name:16s} worst x{worst:.2f}, clean / none {cost:.2f}" if cost else name, flush=True)
    out["summary"] = summary
    out["seeds"] = seed_spread(out)
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")


def seed_spread(out):
    """Per garden and candidate trained at several seeds (``NAME`` is seed 0, ``NAME@S`` seed S): the clean MEDs,
    their mean, min, max and max / min, and the mean MED under each corruption; keys ``garden|NAME``."""
    res = {}
    for key, by_seed in seed_groups(out).items():
        if len(by_seed) < 2:
            continue
        clean = [by_seed[s]["clean"] for s in sorted(by_seed)]
        common = set.intersection(*(set(m) for m in by_seed.values()))
        mean = {c: float(np.mean([m[c] for m in by_seed.values()])) for c in sorted(common)}
        corrupted = {c: v for c, v in mean.items() if c in CORRUPTIONS}  # the eleven every candidate has
        res[key] = {"seeds": sorted(by_seed), "clean": clean, "clean mean": float(np.mean(clean)),
                    "clean min": min(clean), "clean max": max(clean), "clean max over min": max(clean) / min(clean),
                    "mean": mean, "corrupted mean": float(np.mean(list(corrupted.values()))) if corrupted else None,
                    "worst corruption": max(corrupted, key=corrupted.get) if corrupted else None,
                    "worst corruption mean": max(corrupted.values()) if corrupted else None}
    return res


if __name__ == "__main__":
    main()

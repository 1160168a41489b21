"""The training recipes, in one place: what the thesis's configuration and the
sfanav default mean for the readout, the image rows, the number of outputs
and rotation pooling.

* **thesis** (a ``thesis-*`` preset): all image rows, a quadratic regression
  of the 8 slowest outputs, no rotation pooling;
* **sfanav default** (the ``sfanav-default`` preset): the horizon band
  (elevation -10 .. +20 degrees, :func:`default_rows`), the ``"auto"``
  readout on the slowest outputs, and rotation pooling over 8 rotations.

:func:`recipe_for` resolves a recipe from what the user named (a preset, a
config file, explicit overrides); ``sfanav train``, :func:`train_default`
and :class:`sfanav.Localizer` all ask it. Why these choices: docs/gardens.md."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..data.image_rows import ImageRows
from ..sfa.network import Network, Rotation

NETWORK_PRESET = "sfanav-default"


BAND = (-10.0, 20.0)


READOUT = "auto"


CAMERA_ELEVATION = (-30.0, 20.0)  # the simulator's and the thesis's panoramas


def default_network(**overrides: Any) -> Network:
    """An unfitted network of the ``sfanav-default`` preset (350x40 RGB
    input); ``overrides`` as :meth:`sfanav.Network.from_preset`."""
    return Network.from_preset(NETWORK_PRESET, **overrides)


def default_rows(camera_elevation: Sequence[float] = CAMERA_ELEVATION) -> ImageRows:
    """The default image rows: the horizon band (-10 .. +20 degrees) of
    panoramas whose rows span ``camera_elevation`` (degrees, lowest,
    highest; equiangular rows, row 0 highest)."""
    lo, hi = (float(v) for v in camera_elevation)
    return ImageRows(band=BAND, camera_elevation=(lo, hi))


def train_default(images: Any, xy: Any, *, camera_elevation: Sequence[float] = CAMERA_ELEVATION,
                  network: Network | None = None, rotation: Rotation | None = None, progress: bool = False,
                  info: dict[str, Any] | None = None) -> Any:
    """Trains the sfanav default on a training run: ``images`` (N, 40, 350, 3)
    uint8 or float in temporal order, ``xy`` (N, 2) metres. Returns a fitted
    :class:`sfanav.Localizer` (network, rows and readout; ``save`` it as one
    model file). ``network`` replaces the default network (e.g. for other
    image sizes)."""
    from .training import fit_localizer

    net = network if network is not None else default_network()
    return fit_localizer(net, np.asarray(images), np.asarray(xy, float), rotation=rotation or Rotation(5, 1.0),
                         readout=READOUT, rows=default_rows(camera_elevation), progress=progress,
                         info={"configuration": "sfanav default", **(info or {})})

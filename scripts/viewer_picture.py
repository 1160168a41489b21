"""A picture of the Rerun viewer showing a recording (the README's picture of
the live view).

Opens RECORDING (an .rrd written by ``sfanav demo`` or ``localize --rerun``)
in the Rerun viewer with sfanav's default layout
(``sfanav.odometry.live_view.default_blueprint``, side panels collapsed,
the time cursor on the last image), lets the viewer save a screenshot of
itself (``rerun --screenshot-to``) and writes it to OUT (PNG, atomically).
Without a display it runs the viewer under ``xvfb-run`` (Debian: ``xvfb``;
the software renderer ``mesa-vulkan-drivers`` is enough).

    sfanav demo --out sfanav-demo
    python3 scripts/viewer_picture.py sfanav-demo/demo.rrd docs/images/live-view.png
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from sfanav.odometry.live_view import default_blueprint


def screenshot(recording: Path, out: Path, *, size: str = "1000x600", timeout: float = 300.0) -> Path:
    """Writes the viewer's picture of ``recording`` to ``out`` (PNG).
    Raises RuntimeError naming what failed (no viewer, no display, no
    picture written)."""
    rerun = shutil.which("rerun")
    if rerun is None:
        raise RuntimeError("the 'rerun' viewer is not on PATH (pip install rerun-sdk)")
    with tempfile.TemporaryDirectory() as tmp:
        layout = Path(tmp) / "layout.rbl"
        default_blueprint(panels=False).save("sfanav", str(layout))
        shot = Path(tmp) / "shot.png"
        cmd = [rerun, str(recording), str(layout), "--screenshot-to", str(shot), "--window-size", size]
        if not os.environ.get("DISPLAY"):
            xvfb = shutil.which("xvfb-run")
            if xvfb is None:
                raise RuntimeError("no DISPLAY and no xvfb-run (apt-get install xvfb)")
            cmd = [xvfb, "-a", "-s", "-screen 0 1920x1080x24"] + cmd
        # RUST_LOG=error: the viewer shows its warnings (software renderer,
        # container) as notifications, which would land in the picture.
        env = dict(os.environ, RUST_LOG="error")
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)
        if proc.returncode != 0 or not shot.exists():
            raise RuntimeError(f"the viewer wrote no picture (exit {proc.returncode}): {proc.stderr.strip()[-400:]}")
        out.parent.mkdir(parents=True, exist_ok=True)
        part = out.with_name(out.name + ".part")
        shutil.copyfile(shot, part)
        os.replace(part, out)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recording", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--size", default="1000x600", help="window size in logical pixels, WxH")
    a = ap.parse_args(argv)
    if not a.recording.is_file():
        print(f"viewer_picture: no recording at {a.recording}", file=sys.stderr)
        return 2
    try:
        screenshot(a.recording, a.out, size=a.size)
    except (RuntimeError, subprocess.TimeoutExpired) as exc:
        print(f"viewer_picture: {exc}", file=sys.stderr)
        return 1
    print(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

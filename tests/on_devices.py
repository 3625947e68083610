"""Run a script in a fresh Python on K CPU devices and read the JSON object it prints last.

The device count is fixed when JAX starts, so tests comparing a crowd split over devices with
one device run each side in its own process (``XLA_FLAGS``); the child's stderr is shown when it
fails.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any


def run_on_devices(
    script: str, devices: int, stdin: str | None = None, **env_vars: str
) -> dict[str, Any]:
    """``python -c script`` with ``devices`` CPU devices (and ``env_vars`` set); its last
    stdout line as JSON."""
    env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
    env.update(env_vars)
    proc = subprocess.run(
        [sys.executable, "-c", script],
        input=stdin,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, (
        f"{devices} device(s): exit {proc.returncode}\n{proc.stderr[-4000:]}"
    )
    return json.loads(proc.stdout.strip().splitlines()[-1])

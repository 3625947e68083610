"""jcrowd: crowds whose motion is synthesized from motion capture, in JAX.

The public API is re-exported here once; each name is defined in the module that owns it.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from jcrowd.errors import BVHError as BVHError
from jcrowd.errors import DataError as DataError
from jcrowd.errors import JcrowdError as JcrowdError
from jcrowd.errors import MotionError as MotionError
from jcrowd.errors import SkeletonError as SkeletonError

try:
    __version__ = version("jcrowd")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"

"""Scenarios: the TOML schema and its checks, polygon geometry, spawning.

A scenario is a TOML file (keys documented in ``examples/README.md``): :func:`load_scenario`
reads and checks it into a :class:`Scenario` (errors name the file and the key path),
:func:`spawn` places its agents. The modules import in one direction: ``check`` and
``geometry`` → ``schema`` → ``parse`` and ``spawning``.
"""

from jcrowd.scenario.geometry import MIN_POLYGON_AREA_M2 as MIN_POLYGON_AREA_M2
from jcrowd.scenario.geometry import Region as Region
from jcrowd.scenario.geometry import polygon_area as polygon_area
from jcrowd.scenario.geometry import polygon_contains as polygon_contains
from jcrowd.scenario.geometry import polygon_problem as polygon_problem
from jcrowd.scenario.geometry import sample_triangles as sample_triangles
from jcrowd.scenario.geometry import triangulate as triangulate
from jcrowd.scenario.keys import Varied as Varied
from jcrowd.scenario.keys import parse_key_path as parse_key_path
from jcrowd.scenario.keys import varied_parameter as varied_parameter
from jcrowd.scenario.keys import with_values as with_values
from jcrowd.scenario.layout import MAX_SPAWN_DENSITY as MAX_SPAWN_DENSITY
from jcrowd.scenario.layout import Layout as Layout
from jcrowd.scenario.layout import Wall as Wall
from jcrowd.scenario.layout import blocked_space as blocked_space
from jcrowd.scenario.layout import check_layout as check_layout
from jcrowd.scenario.layout import free_space as free_space
from jcrowd.scenario.layout import region_shape as region_shape
from jcrowd.scenario.parse import load_scenario as load_scenario
from jcrowd.scenario.parse import parse_scenario as parse_scenario
from jcrowd.scenario.schema import DEFAULT_THRESHOLDS_M as DEFAULT_THRESHOLDS_M
from jcrowd.scenario.schema import Camera as Camera
from jcrowd.scenario.schema import CameraKey as CameraKey
from jcrowd.scenario.schema import DynamicsSettings as DynamicsSettings
from jcrowd.scenario.schema import Group as Group
from jcrowd.scenario.schema import LodSettings as LodSettings
from jcrowd.scenario.schema import Path as Path
from jcrowd.scenario.schema import Scenario as Scenario
from jcrowd.scenario.schema import Source as Source
from jcrowd.scenario.schema import camera_at as camera_at
from jcrowd.scenario.spawning import LATERAL_JITTER_M as LATERAL_JITTER_M
from jcrowd.scenario.spawning import Spawn as Spawn
from jcrowd.scenario.spawning import spawn as spawn

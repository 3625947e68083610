"""Files: BVH, model and tensor files, datasets, the fit report, shipped resources.

Model and tensor files are safetensors with JSON metadata and a checksum (:mod:`.store`);
every file is written atomically (:func:`write_atomic`). The fit and the step return objects;
this package reads and writes them.
"""

from jcrowd.io.atomic import write_atomic as write_atomic
from jcrowd.io.body_file import with_body_height as with_body_height
from jcrowd.io.bvh import UNIT_SCALES as UNIT_SCALES
from jcrowd.io.bvh import BVHClip as BVHClip
from jcrowd.io.bvh import load_bvh as load_bvh
from jcrowd.io.bvh import read_bvh as read_bvh
from jcrowd.io.bvh_write import write_bvh as write_bvh
from jcrowd.io.dataset import LABEL_COLUMNS as LABEL_COLUMNS
from jcrowd.io.dataset import load_dataset as load_dataset
from jcrowd.io.model_file import load_default_model as load_default_model
from jcrowd.io.model_file import load_motion_model as load_motion_model
from jcrowd.io.model_file import save_motion_model as save_motion_model
from jcrowd.io.report import summary_text as summary_text
from jcrowd.io.report import write_fit_report as write_fit_report
from jcrowd.io.resources import default_model_path as default_model_path
from jcrowd.io.resources import demo_scenario_path as demo_scenario_path
from jcrowd.io.resources import sample_bvh_path as sample_bvh_path
from jcrowd.io.store import FORMAT_VERSION as FORMAT_VERSION
from jcrowd.io.store import load_store as load_store
from jcrowd.io.store import save_store as save_store
from jcrowd.io.store import skeleton_from_json as skeleton_from_json
from jcrowd.io.store import skeleton_to_json as skeleton_to_json
from jcrowd.io.tensor_file import load_tensor_model as load_tensor_model
from jcrowd.io.tensor_file import save_tensor_model as save_tensor_model

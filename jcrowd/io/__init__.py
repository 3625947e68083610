"""File formats: BVH motion files (:mod:`jcrowd.io.bvh`) and, later, model files."""

"""Model files: save → load is bit-identical; any damage is a StoreError naming the file."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from safetensors.numpy import save

from jcrowd.errors import StoreError
from jcrowd.io import (
    FORMAT_VERSION,
    load_store,
    save_store,
    skeleton_from_json,
    skeleton_to_json,
)
from jcrowd.motion import walker_skeleton


def _example() -> tuple[dict[str, np.ndarray], dict]:
    rng = np.random.default_rng(0)
    tensors = {
        "level0/core": rng.normal(size=(4, 5, 6)).astype(np.float32),
        "level0/U_P": rng.normal(size=(30, 4)).astype(np.float32),
        "ids": np.arange(7, dtype=np.int32),
    }
    meta = {
        "controls": ["dx", "dz", "dyaw"],
        "ranges": [[-1.0, 1.0]],
        "skeleton": skeleton_to_json(walker_skeleton(1.8)),
    }
    return tensors, meta


def test_round_trip_is_bit_identical(tmp_path: Path) -> None:
    tensors, meta = _example()
    path = tmp_path / "m.jcm"
    save_store(path, tensors, meta, kind="test-model")
    got, got_meta = load_store(path, kind="test-model")
    assert sorted(got) == sorted(tensors)
    for k in tensors:
        assert got[k].dtype == tensors[k].dtype
        assert got[k].tobytes() == tensors[k].tobytes()
    assert got_meta == json.loads(json.dumps(meta))
    sk = walker_skeleton(1.8)
    back = skeleton_from_json(got_meta["skeleton"])
    assert back.names == sk.names and back.parents == sk.parents
    assert np.asarray(back.offsets).tobytes() == np.asarray(sk.offsets, np.float32).tobytes()
    # Saving the loaded data again gives the same file, byte for byte.
    save_store(tmp_path / "again.jcm", got, got_meta, kind="test-model")
    assert (tmp_path / "again.jcm").read_bytes() == path.read_bytes()
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_flipped_byte_in_data_is_caught(tmp_path: Path) -> None:
    tensors, meta = _example()
    path = tmp_path / "m.jcm"
    save_store(path, tensors, meta, kind="test-model")
    data = bytearray(path.read_bytes())
    data[-5] ^= 0x01  # inside the last tensor's bytes: safetensors alone would load it
    path.write_bytes(bytes(data))
    with pytest.raises(StoreError, match=r"m\.jcm: checksum mismatch"):
        load_store(path)


def test_flipped_byte_in_header_is_caught(tmp_path: Path) -> None:
    tensors, meta = _example()
    path = tmp_path / "m.jcm"
    save_store(path, tensors, meta, kind="test-model")
    data = bytearray(path.read_bytes())
    data[12] ^= 0x40
    path.write_bytes(bytes(data))
    with pytest.raises(StoreError, match=r"m\.jcm"):
        load_store(path)


@pytest.mark.parametrize("keep", [0, 5, 40, -3])
def test_truncated_file_is_caught(tmp_path: Path, keep: int) -> None:
    tensors, meta = _example()
    path = tmp_path / "m.jcm"
    save_store(path, tensors, meta, kind="test-model")
    data = path.read_bytes()
    path.write_bytes(data[:keep])  # a negative keep cuts the tail
    with pytest.raises(StoreError, match=r"m\.jcm: .*(truncated|expected)"):
        load_store(path)


def test_future_version_and_wrong_kind(tmp_path: Path) -> None:
    tensors, meta = _example()
    doc = {
        "format": "jcrowd-model",
        "format_version": FORMAT_VERSION + 1,
        "kind": "test-model",
        "jcrowd_version": "9.0",
        "sha256": "",
        "meta": meta,
    }
    path = tmp_path / "future.jcm"
    path.write_bytes(save(tensors, metadata={"jcrowd": json.dumps(doc)}))
    with pytest.raises(
        StoreError, match=r"future\.jcm: format version 2; this jcrowd reads versions 1\.\.1"
    ):
        load_store(path)
    save_store(tmp_path / "m.jcm", tensors, meta, kind="test-model")
    with pytest.raises(StoreError, match=r"expected a 'motion-model' file, found 'test-model'"):
        load_store(tmp_path / "m.jcm", kind="motion-model")


def test_other_files_are_not_model_files(tmp_path: Path) -> None:
    plain = tmp_path / "plain.safetensors"
    plain.write_bytes(save({"a": np.zeros(3, np.float32)}))
    with pytest.raises(StoreError, match="without jcrowd metadata"):
        load_store(plain)
    bvh = tmp_path / "walk.bvh"
    bvh.write_text("HIERARCHY\nROOT Hips\n{\n}\n")
    with pytest.raises(StoreError, match=r"walk\.bvh"):
        load_store(bvh)
    with pytest.raises(StoreError, match=r"missing\.jcm: cannot read"):
        load_store(tmp_path / "missing.jcm")


def test_failed_write_keeps_the_old_file(tmp_path: Path) -> None:
    tensors, meta = _example()
    path = tmp_path / "m.jcm"
    save_store(path, tensors, meta, kind="test-model")
    before = path.read_bytes()
    with pytest.raises(StoreError, match="not JSON-serialisable"):
        save_store(path, tensors, {"bad": object()}, kind="test-model")
    with pytest.raises(StoreError, match="cannot write"):
        save_store(tmp_path / "no" / "such" / "dir.jcm", tensors, meta, kind="test-model")
    assert path.read_bytes() == before
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]

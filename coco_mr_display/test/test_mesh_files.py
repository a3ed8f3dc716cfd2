"""A mesh is read only from a regular file of bounded size: a device or a FIFO named as a mesh is a
clear error, not an endless read or a blocked loader."""

import os

import pytest

from coco_core.errors import MeshLoadError
from coco_mr_display.mesh import load_geometry


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_a_device_is_not_a_mesh(device):
    with pytest.raises(MeshLoadError, match=f"mesh {device} is a character device, not a regular file"):
        load_geometry(device)


def test_a_fifo_is_refused_without_blocking(tmp_path):
    os.mkfifo(tmp_path / "part.stl")
    with pytest.raises(MeshLoadError, match="is a FIFO, not a regular file"):
        load_geometry(tmp_path / "part.stl")


def test_a_mesh_file_is_still_read_from_its_bytes(tmp_path):
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert len(load_geometry(tmp_path / "tri.obj").faces) == 1

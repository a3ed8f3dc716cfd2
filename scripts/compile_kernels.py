"""Compile the numba kernels of coco_mr_haptics and coco_mr_vision into numba's cache of the installed
packages, once, before the test suites start.

On a fresh build the cache is empty, and every process that first calls a kernel compiles it (about
15 s of CPU for the haptic kernels alone): the suites run side by side, so several processes (the
haptics and vision tests, the workspace apps) compiled the same kernels at the same time on the two
cores, and a cloud test took up to three minutes. Done here once, those processes read the cache (a
second's load). The calls are the components' own warm-ups (what they do when configured), for the
argument types the applications use: the god-object step, the cloud fits, and the meshing passes at
stride 1 (contiguous) and 2 (strided, a version of its own).
"""

from __future__ import annotations

import time


def main() -> int:
    start = time.perf_counter()
    from coco_core.application import Application
    from coco_mr_haptics.local_surface import warm_up as fits_warm_up
    from coco_mr_haptics.proxy import warm_up as step_warm_up
    from coco_mr_vision.mesh_reconstructor import MeshReconstructor

    step_warm_up()
    fits_warm_up()
    app = Application("compile_kernels")
    for stride in (1, 2):
        mesher = app.add(MeshReconstructor(f"mesher_{stride}", stride=stride))
        if not mesher.configure():
            print(f"MeshReconstructor (stride {stride}) failed to configure: see the log above")
            return 1
    print(f"numba kernels compiled or loaded from the cache in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

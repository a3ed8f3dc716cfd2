"""A shader program's uniform by name, typed.

moderngl's ``program[name]`` returns a uniform, a uniform block, a vertex attribute or a varying;
a peer that writes a matrix or a vector means a uniform, and a name that is something else (or a
uniform the GLSL compiler removed because the shader does not use it) is a bug in the shader pair,
reported here with the names the program does have.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from coco_core.errors import UnknownNameError, did_you_mean

if TYPE_CHECKING:
    import moderngl


def uniform(program: moderngl.Program, name: str) -> moderngl.Uniform:
    """``program``'s uniform ``name``."""
    import moderngl

    member = program.get(name, None)
    if not isinstance(member, moderngl.Uniform):
        names = [key for key in program if isinstance(program.get(key, None), moderngl.Uniform)]
        raise UnknownNameError(f"shader program has no uniform {name!r}: {did_you_mean(name, names)}")
    return member

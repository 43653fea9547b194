"""The device buffers a frame's stages allocate, each declared once beside its stage
(`BufferDecl`): what it holds, its element's bytes and its length as a function of the
frame's sizes (`FrameSizes`, which clrays.inputs.frame_sizes takes from a frame's inputs).
A stage allocates the buffer through its declaration, and
clrays.frame_memory.frame_buffer_bytes sums the declarations of the stages a frame runs
before anything is allocated, so that the prediction the refusal check reads and the allocation
cannot drift apart. The device counts the bytes allocated under each declaration's name
(Device.allocated_by_name), which tests/stages/test_frame_buffers.py holds against the
prediction.

    TREE = BufferDecl("min-max tree", 8, lambda sizes: sizes.slices * 2 * sizes.tree_gamma)
    tree = TREE.allocate(device, frame_sizes(buffers.inputs))
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable


@dataclass(frozen=True)
class FrameSizes:
    """The sizes a frame's buffers follow, from its inputs (`frame_sizes`, which gives each);
    one left out is 0 (a stage's test that sizes a buffer by its samples alone)."""

    samples: int = 0  # camera samples: pixels × spp
    pixels: int = 0
    lights: int = 0  # the lights of these inputs (one for a light in its turn: clrays.light_turns)
    shadow_texels: int = 0  # every shadow map of these inputs, back to back (one light's: `for_light`)
    light_texels: tuple[int, ...] = ()  # each light's shadow-map texels
    slices: int = 0  # epipolar slices (render.slices)
    tree_gamma: int = 0  # γ texels of a min-max tree's row (tree_gamma_samples)
    line_samples: int = 0  # epipolar sampling's samples per line
    svd_rank: int = 0  # a textured light's γ basis (render.svd_rank)
    layers: int = 0  # translucent layers per shadow-map texel (render.translucent_layers)
    triangles: int = 0  # the scene's
    texture_texels: int = 0  # every light's texture texels, packed (clrays.inputs.FrameInputs.texels)
    film_slots: int = 0  # the camera's translucent films per sample (clrays.stages.transparency)

    @property
    def entries(self) -> int:
        """Per camera sample and light (at least one light)."""
        return self.samples * max(self.lights, 1)

    def for_light(self, index: int) -> FrameSizes:
        """The sizes of light `index`'s own buffers: its shadow maps alone."""
        return replace(self, shadow_texels=self.light_texels[index])


@dataclass(frozen=True)
class BufferDecl:
    """One device buffer a stage allocates: `name`, what it holds (as the refusal of a frame
    too big names it); `element_bytes`, its element's size (its dtype's itemsize, or its
    struct's); `length`, its elements from the frame's sizes. `bound`: the length is the
    most the stage may take, not what it always takes (a list of what the device finds)."""

    name: str
    element_bytes: int
    length: Callable[[FrameSizes], int]
    bound: bool = False

    def nbytes(self, sizes: FrameSizes) -> int:
        return self.element_bytes * int(self.length(sizes))

    def allocate(self, device, sizes: FrameSizes):
        """The buffer, of `nbytes(sizes)` uninitialised bytes, counted under its name."""
        return device.buffer(nbytes=self.nbytes(sizes), name=self.name)

    def upload(self, device, array, sizes: FrameSizes):
        """A read-only buffer filled from `array`, which holds `length(sizes)` elements (at
        most, where the length is a bound)."""
        if array.nbytes > self.nbytes(sizes) or (array.nbytes != self.nbytes(sizes) and not self.bound):
            raise ValueError(f"{self.name}: {array.nbytes} bytes to upload, declared {self.nbytes(sizes)}")
        return device.buffer(array, writable=False, name=self.name)

"""A light's texture on the host, in float64: where a light ray meets the texture, the
bilinear texel value there, and the `exact` reference's in-scattering of a textured light
(docs/light-textures.md).

The texture multiplies the light's power per light ray (docs/light-textures.md, "What a
texture means"):

    spot:        the light ray through x, w = x - l, meets the plane at distance 1 along
                 the axis at (w·right, w·up)/(w·axis); the image fills [-tan c, tan c]²
                 of that plane (the square around the cone), image up along `up`.
    directional: x projected along the light's direction onto the plane through the
                 world origin: (x·right, x·up); one copy of the image covers
                 texture_size, centred on the origin; `repeat` tiles it, `clamp` extends
                 its edge texels.
    point:       a cube: the face of w = x - l's major axis, seen from the light along
                 its axis F with up U (CUBE_FACES): (w·(F × U), w·U)/(w·F).

Both give screen coordinates (sx, sy) in [-1, 1] over the image, then texel coordinates
x_t = (sx + 1)/2·W, y_t = (1 - sy)/2·H (row 0 on top) like a view's (cl/lighting.h), and a
bilinear lookup between texel centres i + ½. `cl/light_texture.h` is the same on the device.

`textured_in_scatter` integrates lit segments with the texture: the bilinear lookup has
kinks where a texel coordinate crosses a texel centre, so each segment is cut there (the
light ray through a point of a camera ray moves monotonically across the image: a straight
line in the image for a spot light or a cube face, a straight line in the plane for a
directional one; a cube texture is cut where the ray changes face first) and every piece
is integrated by Gauss–Legendre, where the integrand is smooth.

`pack_light_textures` writes that mapping as the device's light_texture_t per light, for
the frame's inputs (clrays.inputs) and the kernels that look a texture up per point.
"""
from __future__ import annotations

import math

import numpy as np

from .. import structs
from ..scene.model import DirectionalLight, Light, Medium, SpotLight
from ..scene.textures import TexelCrossingsError
from .radiometry import phase, rgb

#: Gauss–Legendre nodes per piece between texel-centre crossings (each piece is at most a
#: texel across, and smooth): 8 agree with 32 to 1e-9 on the test scenes' segments. A
#: directional light's piece is a quadratic (the bilinear texels along a line) times
#: e^{-σt·s}: 3 nodes are exact for the quadratic times a cubic, and agree with 8 to 1e-10.
PIECE_NODES = 8
PIECE_NODES_DIRECTIONAL = 3
# Pieces integrated per batch (pieces × nodes × 3 channels float64 temporaries ≈ 50 MB).
_PIECE_BATCH = 200_000
#: Texel-centre crossings `exact` cuts the segments of one call at (a batch of camera rays,
#: both texture axes): about 80 bytes and 2 µs each (measured: 9.0 M crossings, 747 MB
#: and 21 s at 32×18). A directional light's `texture_size: [1e-6, 1e-6]` asked for
#: 2.6e10 of them, capped silently at 65536 a segment: 90 s and 5.5 GB (docs/limits.md).
MAX_TEXEL_CROSSINGS = 1 << 23


def textured(light: Light) -> bool:
    return getattr(light, "texture", None) is not None


def texture_frame(direction) -> tuple[np.ndarray, np.ndarray]:
    """(right, up): the texture's axes for a light shining along `direction` (unit).
    up is world +y projected off the direction, or -z when the light shines within ~26° of
    ±y (a stage light pointing down: the image's top then lies towards -z)."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    hint = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.array([0.0, 0.0, -1.0])
    right = np.cross(d, hint)
    right /= np.linalg.norm(right)
    return right, np.cross(right, d)


#: A point light's cube texture faces, in the order of its six images: the direction each
#: looks along and its up, as the cube shadow map's faces (clrays/inputs.py); right = F × U.
CUBE_FACES = np.array([
    [[1, 0, 0], [0, 1, 0]], [[-1, 0, 0], [0, 1, 0]],
    [[0, 1, 0], [0, 0, 1]], [[0, -1, 0], [0, 0, 1]],
    [[0, 0, 1], [0, 1, 0]], [[0, 0, -1], [0, 1, 0]],
], dtype=np.float64)


def _rows(light: Light, face: int = 0) -> np.ndarray:
    """(3, 4): the projective map x -> (sx, sy) of the light's texture as rows acting on
    [x, 1]: sx = row_0·[x, 1] / row_2·[x, 1], sy = row_1·[x, 1] / row_2·[x, 1] (for a point
    light, of cube face `face`)."""
    if isinstance(light, DirectionalLight):
        right, up = texture_frame(light.direction)
        w, h = light.texture_size
        return np.array([np.append(2.0 * right / w, 0.0), np.append(2.0 * up / h, 0.0), [0.0, 0.0, 0.0, 1.0]])
    l = np.asarray(light.position, dtype=np.float64)
    if isinstance(light, SpotLight):
        right, up = texture_frame(light.direction)
        axis = np.asarray(light.direction, dtype=np.float64) / np.linalg.norm(light.direction)
        scale = 1.0 / math.tan(math.radians(light.cone_deg))
    else:
        axis, up = CUBE_FACES[face]
        right, scale = np.cross(axis, up), 1.0
    return np.array([np.append(v * k, -(v @ l) * k) for v, k in ((right, scale), (up, scale), (axis, 1.0))])


def cube_face(light: Light, points) -> np.ndarray:
    """The cube face (0..5: +x, -x, +y, -y, +z, -z) of the light ray through each point: its
    major axis, ties to x, then y (as cl/lighting.h light_view_index)."""
    w = np.asarray(points, dtype=np.float64).reshape(-1, 3) - light.position
    a = np.abs(w)
    axis = np.where((a[:, 0] >= a[:, 1]) & (a[:, 0] >= a[:, 2]), 0, np.where(a[:, 1] >= a[:, 2], 1, 2))
    return 2 * axis + (w[np.arange(len(w)), axis] < 0)


def _face_size(light: Light) -> tuple[int, int]:
    """(width, height) of one image of the texture: the whole texture, or one cube face."""
    texture = light.texture
    return (texture.width, texture.width) if _is_cube(light) else (texture.width, texture.height)


def _is_cube(light: Light) -> bool:
    return not isinstance(light, (SpotLight, DirectionalLight))


def texel_coordinates(light: Light, points) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(fx, fy, valid, face): continuous texel coordinates less ½ (so texel centres sit on
    integers) within the image (or cube face `face`) of the light ray through each point,
    and whether that ray has a texel (a spot light's rays behind it have none)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    ph = np.concatenate([p, np.ones((len(p), 1))], axis=1)
    face = cube_face(light, p) if _is_cube(light) else np.zeros(len(p), dtype=np.int64)
    rows = np.stack([_rows(light, f) for f in range(6 if _is_cube(light) else 1)])[face]  # (N, 3, 4)
    value = np.einsum("nrk,nk->nr", rows, ph)
    valid = value[:, 2] > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        sx = np.where(valid, value[:, 0] / value[:, 2], 0.0)
        sy = np.where(valid, value[:, 1] / value[:, 2], 0.0)
    width, height = _face_size(light)
    return (sx + 1.0) * 0.5 * width - 0.5, (1.0 - sy) * 0.5 * height - 0.5, valid, face


def _wrap(index: np.ndarray, n: int, repeat: bool) -> np.ndarray:
    return np.mod(index, n) if repeat else np.clip(index, 0, n - 1)


def bilinear(light: Light, fx, fy, face=None) -> np.ndarray:
    """Texels (N, 3) at texel coordinates (fx, fy) (texel centres on integers) of the image,
    or of cube face `face` (clamped at the face's edges; faces stacked in the texels' rows)."""
    texels = light.texture.texels  # float32: what is gathered is widened, not the whole (400 MB at 4096²)
    width, height = _face_size(light)
    repeat = isinstance(light, DirectionalLight) and light.texture_wrap == "repeat"
    fx = np.clip(fx, -1e9, 1e9)
    fy = np.clip(fy, -1e9, 1e9)
    x0, y0 = np.floor(fx), np.floor(fy)
    tx, ty = (fx - x0)[:, None], (fy - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xa, xb = _wrap(x0, width, repeat), _wrap(x0 + 1, width, repeat)
    ya, yb = _wrap(y0, height, repeat), _wrap(y0 + 1, height, repeat)
    if face is not None and _is_cube(light):
        ya, yb = ya + face * height, yb + face * height
    top = (1 - tx) * texels[ya, xa] + tx * texels[ya, xb]
    bottom = (1 - tx) * texels[yb, xa] + tx * texels[yb, xb]
    return (1 - ty) * top + ty * bottom


def light_texture(light: Light, points) -> np.ndarray:
    """The texture's factor (N, 3) on the light reaching each point (1 for an untextured light)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not textured(light):
        return np.ones((len(p), 3))
    fx, fy, valid, face = texel_coordinates(light, p)
    return np.where(valid[:, None], bilinear(light, fx, fy, face), 0.0)


# --------------------------------------------------------------------------- exact in-scattering


def _crossings(f0: np.ndarray, f1: np.ndarray, s_of, limit: int = MAX_TEXEL_CROSSINGS):
    """Where a coordinate monotone along each segment, f0 at its start and f1 at its end,
    crosses an integer: (segment index, s), using s_of(segment, k) for the s where it is k.
    Counted before any is made: more than `limit` is a TexelCrossingsError."""
    lo, hi = np.minimum(f0, f1), np.maximum(f0, f1)
    first = np.ceil(lo)
    counts = np.maximum(np.floor(hi) - first + 1, 0)
    total = float(counts.sum())
    if total > limit:
        raise TexelCrossingsError(f"exact: the rays cross about {total:.3g} texel centres of a light's texture, "
                                  f"more than the {MAX_TEXEL_CROSSINGS} that exact integrates piece by piece (a "
                                  f"texture_size far smaller than the scene tiles it that often); use a larger "
                                  f"texture_size or another method")
    count = counts.astype(np.int64)
    segment = np.repeat(np.arange(len(f0)), count)
    k = first[segment] + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
    return segment, s_of(segment, k)


def _pieces(light: Light, origins, dirs, a, b):
    """Cut each segment [a, b] of x(s) = o + s·v where a texel coordinate crosses a texel
    centre (and, for a cube texture, where the ray changes face first): (segment index,
    piece start, piece end), pieces sorted within each segment."""
    m = len(a)
    if not _is_cube(light):
        return _texel_pieces(origins, dirs, a, b, np.arange(m), np.broadcast_to(_rows(light), (m, 3, 4)),
                             _face_size(light))
    # Face changes: where two components of w(s) = (o - l) + s·v are equal in size.
    q, cuts_segment, cuts_s = origins - light.position, [np.arange(m), np.arange(m)], [a, b]
    for i, j in ((0, 1), (0, 2), (1, 2)):
        for sign in (1.0, -1.0):
            with np.errstate(divide="ignore", invalid="ignore"):
                s = -(q[:, i] - sign * q[:, j]) / (dirs[:, i] - sign * dirs[:, j])
            keep = np.isfinite(s) & (s > a) & (s < b)
            cuts_segment.append(np.flatnonzero(keep))
            cuts_s.append(s[keep])
    segment, lo, hi = _sorted_pieces(np.concatenate(cuts_segment), np.concatenate(cuts_s))
    middle = origins[segment] + (0.5 * (lo + hi))[:, None] * dirs[segment]
    faces = cube_face(light, middle)
    rows = np.stack([_rows(light, f) for f in range(6)])[faces]
    return _texel_pieces(origins[segment], dirs[segment], lo, hi, segment, rows, _face_size(light))


def _sorted_pieces(segment, s):
    order = np.lexsort((s, segment))
    segment, s = segment[order], s[order]
    same = segment[1:] == segment[:-1]
    return segment[:-1][same], s[:-1][same], s[1:][same]


def _texel_pieces(origins, dirs, a, b, owner, rows, size):
    """Cut segments [a, b] (each within one projective map `rows` (M, 3, 4)) at texel-centre
    crossings; (owner of each piece, start, end)."""
    m = len(a)
    oh = np.concatenate([origins, np.ones((m, 1))], axis=1)
    vh = np.concatenate([dirs, np.zeros((m, 1))], axis=1)
    d0, d1 = np.einsum("mk,mk->m", rows[:, 2], oh), np.einsum("mk,mk->m", rows[:, 2], vh)
    cuts_segment, cuts_s = [np.arange(m), np.arange(m)], [a, b]
    crossed = 0  # both axes together: MAX_TEXEL_CROSSINGS
    for axis, n_texels, sign in ((0, size[0], 1.0), (1, size[1], -1.0)):
        # Texel coordinate f(s) = (sign·N(s)/D(s) + 1)·n/2 - ½, N and D linear in s.
        n0, n1 = np.einsum("mk,mk->m", rows[:, axis], oh), np.einsum("mk,mk->m", rows[:, axis], vh)

        def f(s):
            with np.errstate(divide="ignore", invalid="ignore"):
                return (sign * (n0 + s * n1) / (d0 + s * d1) + 1.0) * 0.5 * n_texels - 0.5

        def s_of(segment, k):
            c = sign * (2.0 * (k + 0.5) / n_texels - 1.0)  # N(s)/D(s) = c
            with np.errstate(divide="ignore", invalid="ignore"):
                return (c * d0[segment] - n0[segment]) / (n1[segment] - c * d1[segment])

        f_a, f_b = f(a), f(b)
        ok = np.isfinite(f_a) & np.isfinite(f_b)
        segment, s = _crossings(np.where(ok, f_a, 0.0), np.where(ok, f_b, 0.0), s_of,
                                MAX_TEXEL_CROSSINGS - crossed)
        crossed += len(segment)
        keep = np.isfinite(s) & (s > a[segment]) & (s < b[segment])
        cuts_segment.append(segment[keep])
        cuts_s.append(s[keep])
    piece, lo, hi = _sorted_pieces(np.concatenate(cuts_segment), np.concatenate(cuts_s))
    return owner[piece], lo, hi


def textured_in_scatter(light: Light, medium: Medium, origins, dirs, a, b) -> np.ndarray:
    """In-scattered radiance (M, 3) of a textured light from lit segments s ∈ [a, b] of rays
    x(s) = o + s·v (v unit): ∫ e^{-σt·s}·σs·ρ(cosθ)·Lin(x_s)·T(x_s) ds, T the bilinear
    texture factor (module docstring). The same model as `radiometry.in_scatter_segments`,
    which it equals for a white texture (to 1e-9, tests/methods/test_light_texture.py).

    Pieces between texel-centre crossings get PIECE_NODES Gauss–Legendre nodes each, in
    s for a directional light and in the angle φ at the light (s = s0 + h·tanφ, which
    takes away the 1/d² peak, as in_scatter_segments does) for a spot light."""
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    m = len(dirs)
    out = np.zeros((m, 3))
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), (m, 3))
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), (m,)).copy()
    b = np.broadcast_to(np.asarray(b, dtype=np.float64), (m,)).copy()
    live = np.flatnonzero(b > a)
    if len(live) == 0:
        return out
    segment, p0, p1 = _pieces(light, origins[live], dirs[live], a[live], b[live])
    segment = live[segment]
    sigma_s = rgb(medium.sigma_s)
    sigma_t = sigma_s + rgb(medium.sigma_a)
    directional = isinstance(light, DirectionalLight)
    nodes, weights = np.polynomial.legendre.leggauss(PIECE_NODES_DIRECTIONAL if directional else PIECE_NODES)
    if directional:
        w = np.asarray(light.direction, dtype=np.float64)
        w /= np.linalg.norm(w)
        power = rgb(light.irradiance)
    else:
        power = rgb(light.intensity)
    for start in range(0, len(segment), _PIECE_BATCH):
        seg = segment[start:start + _PIECE_BATCH]
        lo, hi = p0[start:start + _PIECE_BATCH], p1[start:start + _PIECE_BATCH]
        o, v = origins[seg], dirs[seg]
        if directional:
            s = 0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * nodes  # (P, G)
            weight = 0.5 * (hi - lo)[:, None] * weights
            rho = phase(-(v @ w), medium.phase)[:, None]
            factor = weight * rho
            path = s
        else:
            to_light = light.position - o
            s0 = np.einsum("ij,ij->i", to_light, v)
            h = np.linalg.norm(to_light - s0[:, None] * v, axis=1)
            h = np.maximum(h, 1e-12 * (np.linalg.norm(to_light, axis=1) + np.abs(lo) + np.abs(hi)))
            phi0, phi1 = np.arctan2(lo - s0, h), np.arctan2(hi - s0, h)
            phi = 0.5 * (phi0 + phi1)[:, None] + 0.5 * (phi1 - phi0)[:, None] * nodes
            s = s0[:, None] + h[:, None] * np.tan(phi)
            d = h[:, None] / np.cos(phi)
            # ds/d² = dφ/h; cosθ = -(x - l)/d · v = -sinφ (radiometry.in_scatter_segments).
            factor = 0.5 * (phi1 - phi0)[:, None] * weights * phase(-np.sin(phi), medium.phase) / h[:, None]
            path = s + d
        points = o[:, None, :] + s[..., None] * v[:, None, :]
        texture = light_texture(light, points.reshape(-1, 3)).reshape(*s.shape, 3)
        value = np.einsum("pg,pgc->pc", factor, texture * np.exp(-sigma_t * path[..., None]))
        for channel in range(3):
            out[:, channel] += np.bincount(seg, weights=value[:, channel], minlength=m)
    return out * sigma_s * power


def pack_light_textures(scene, eye_ws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(light_texture_t per light, float4 texels of every texture one after another) for a
    scene in eye space (at least one texel, so the buffer exists). Lights that share a
    texture (the loader gives them one array: clrays.scene.textures.TextureCache) share its
    texels here too: 16 spot lights with one 4096² gobo hold 256 MiB, not 4 GiB."""
    entries = np.zeros(max(len(scene.lights), 1), dtype=structs.light_texture_dtype)
    first_of: dict[int, int] = {}  # id(texels) -> its first texel in the packed buffer
    unique, total = [], 0
    for index, light in enumerate(scene.lights):
        if not textured(light):
            continue
        entry = entries[index]
        right, up = texture_frame(light.direction) if hasattr(light, "direction") else (np.zeros(3), np.zeros(3))
        entry["right"], entry["up"] = structs.float4(right), structs.float4(up)
        entry["origin"] = structs.float4(-np.asarray(eye_ws, dtype=np.float64))  # the world origin
        if isinstance(light, SpotLight):
            entry["scale_x"] = entry["scale_y"] = 1.0 / math.tan(math.radians(light.cone_deg))
            entry["wrap"] = structs.TEXTURE_WRAP_CLAMP
        elif not isinstance(light, DirectionalLight):  # a point light's cube: its faces fix the frame
            entry["scale_x"] = entry["scale_y"] = 1.0
            entry["wrap"] = structs.TEXTURE_WRAP_CLAMP
        else:
            entry["scale_x"], entry["scale_y"] = 1.0 / light.texture_size[0], 1.0 / light.texture_size[1]
            entry["wrap"] = structs.TEXTURE_WRAP_REPEAT if light.texture_wrap == "repeat" else structs.TEXTURE_WRAP_CLAMP
        texels = light.texture.texels
        if id(texels) not in first_of:
            first_of[id(texels)] = total
            unique.append(texels)
            total += light.texture.height * light.texture.width
        entry["first_texel"], entry["width"], entry["height"] = first_of[id(texels)], light.texture.width, \
            light.texture.height
        entry["textured"] = 1
    packed = np.zeros((max(total, 1), 4), dtype=np.float32)  # one array: no per-texture copies to join
    for texels in unique:
        first = first_of[id(texels)]
        packed[first:first + texels.shape[0] * texels.shape[1], :3] = texels.reshape(-1, 3)
    return entries, packed

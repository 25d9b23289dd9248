"""moderngl stereo renderer: draws the (deformed) object for the left and right eye into projector pixels.

Pipeline per eye (all in the vertex shader ``shaders/correct.vert``, the same math as
:mod:`flexsheet.rendering.correction`): vertex A → corrected A' (model
``none``/``flat``/``four_triangle``/``fine``) → its screen point on the line eye–A' → the projector pixel that
lights it: the registered projector (``display.yaml``: intrinsics K_p, OpenCV distortion D, axes R and centre
P in the display frame), so the imaginary-screen → pixel mapping is the calibration's, not a constant. Output:
two RGB images of ``width × height`` projector pixels (left eye at V − IPD/2·ŷ, right at V + IPD/2·ŷ: the user
faces −x, so +y is the user's right).

The GL context is moderngl's standalone EGL context (headless; llvmpipe on machines without a GPU), or the
context of a projector window (:mod:`nodes.renderer.window`, ``ctx=``): the drawing is the same, only the
output target differs. All GL calls must come from the thread that created the renderer.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.projector import Projector, eye_positions
from flexsheet.model.scene_surface import cylinder_surface
from flexsheet.model.sheet import SheetSurface
from flexsheet.model.sheet_model import GRID_STEP, SampledShape, grid_size
from flexsheet.rendering.correction import DEFAULT_MIN_COS, fan_triangles

__all__ = ["StereoRenderer", "cylinder_draw_mesh", "scaled_projector", "vertex_normals", "sampled",
           "MODE_IDS",
           "DEPTH_UNIT"]

SHADER_DIR = Path(__file__).with_name("shaders")
MODE_IDS = {"none": 0, "flat": 1, "four_triangle": 2, "fine": 3}
#: texture unit of the fine model's depth table
DEPTH_UNIT = 0


def cylinder_draw_mesh(radius: float = geometry.CYLINDER_RADIUS, length: float = geometry.CYLINDER_LENGTH,
                       center=geometry.CYLINDER_CENTER, n_around: int = 96, n_along: int = 48):
    """Closed cylinder with axis along +y through ``center`` (3,) m, finely tessellated along the axis
    (per-vertex correction needs short edges on a curved sheet):
    :func:`flexsheet.model.scene_surface.cylinder_surface` (the mesh of the cylinder scene). Returns (vertices
    (N, 3) float32 m, faces (M, 3) int32, wound counter-clockwise seen from outside). Raises ``ValueError``
    for a bad size or tessellation."""
    v, f = cylinder_surface(radius, length, n_around, n_along)
    return (v + np.asarray(center, dtype=float)).astype(np.float32), f.astype(np.int32)


def scaled_projector(projector: Projector, width: int | None = None, height: int | None = None) -> Projector:
    """The same projector drawn at another resolution ``width`` × ``height`` px (None keeps its own): the
    intrinsics scale with the pixel grid (f·s, (c + ½)·s − ½), so every pixel still maps to the same ray and
    the image covers the same field of view. Raises ``ValueError`` for a size < 1."""
    W = projector.width if width is None else int(width)
    H = projector.height if height is None else int(height)
    if W < 1 or H < 1:
        raise ValueError(f"width/height must be >= 1, got {W}x{H}")
    if (W, H) == (projector.width, projector.height):
        return projector
    sx, sy = W / projector.width, H / projector.height
    S = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
    return Projector(S @ np.asarray(projector.K, dtype=float), np.asarray(projector.R, dtype=float).copy(),
                     np.asarray(projector.position, dtype=float).copy(), W, H)


def sampled(shape) -> SampledShape:
    """``shape`` as the fine shader draws it: a :class:`SampledShape` as it is, any other pushed-sheet shape
    sampled every :data:`~flexsheet.model.sheet_model.GRID_STEP` over its sheet (the numpy twin of the drawing
    corrects for this)."""
    if isinstance(shape, SampledShape):
        return shape
    return SampledShape.of(shape, *grid_size(shape.half_span, shape.half_width, GRID_STEP))


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (N, 3) float32 (unit; zero where a vertex has no area)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for i in range(3):
        np.add.at(n, f[:, i], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.where(ln > 0, ln, 1.0)).astype(np.float32)


@dataclass
class _Uniforms:
    mode: str = "none"
    values: dict = field(default_factory=dict)


class StereoRenderer:
    """Stereo renderer of a triangle mesh with per-vertex correction (moderngl; headless EGL or a window's
    context).

    ``projector``: :class:`Projector` (its width × height is the output size); ``distortion``: the projector's
    OpenCV distortion (k1, k2, p1, p2, k3) (5,) or None (pinhole), applied per vertex exactly as
    ``cv2.projectPoints``; ``eye`` (3,) cyclopean eye V, m; ``ipd`` m; ``screen_point``/``screen_normal`` the
    imaginary screen; ``samples``: MSAA samples (0 = off); ``ctx``: an existing moderngl context (default: a
    new standalone EGL context). Raises ``RuntimeError`` if no EGL context can be created.
    """

    def __init__(self, projector: Projector | None = None, *, eye=geometry.EYE, ipd: float = 0.064,
                 screen_point=geometry.SCREEN_POINT, screen_normal=geometry.SCREEN_NORMAL, samples: int = 0,
                 min_cos: float = DEFAULT_MIN_COS, near: float = 0.05, far: float = 3.0, ctx=None,
                 color=(1.0, 1.0, 1.0), shading: bool = True, distortion=None) -> None:
        import moderngl

        self.moderngl = moderngl
        self.projector = projector or Projector.default()
        D = np.zeros(5) if distortion is None else np.asarray(distortion, dtype=float).ravel()
        if D.shape != (5,) or not np.all(np.isfinite(D)):
            raise ValueError("distortion must be 5 finite OpenCV coefficients (k1, k2, p1, p2, k3), got "
                             f"{distortion!r}")
        self.distortion = D
        self.eye = np.asarray(eye, dtype=float)
        self.ipd = float(ipd)
        self.eyes = eye_positions(self.eye, self.ipd)
        self.screen_point = np.asarray(screen_point, dtype=float)
        self.screen_normal = np.asarray(screen_normal, dtype=float) / np.linalg.norm(screen_normal)
        self.min_cos = float(min_cos)
        self.owns_ctx = ctx is None
        if ctx is None:
            try:
                ctx = moderngl.create_standalone_context(backend="egl")
            except Exception as exc:  # pragma: no cover - depends on the machine
                raise RuntimeError(f"cannot create a headless EGL OpenGL context: {exc}") from exc
        self.ctx = ctx
        vs = (SHADER_DIR / "correct.vert").read_text()
        fs = (SHADER_DIR / "shade.frag").read_text()
        self.prog = ctx.program(vertex_shader=vs, fragment_shader=fs)
        self.tf_prog = ctx.program(vertex_shader=vs, varyings=["v_corrected", "v_valid", "v_pixel"])
        W, H = self.projector.width, self.projector.height
        self.samples = int(samples)
        self.fbo = ctx.framebuffer(color_attachments=[ctx.texture((2 * W, H), 3)],
                                   depth_attachment=ctx.depth_renderbuffer((2 * W, H)))
        self.msaa = None
        if self.samples > 0:
            self.msaa = ctx.framebuffer(color_attachments=
                                            [ctx.renderbuffer((2 * W, H), 3, samples=self.samples)],
                                        depth_attachment=ctx.depth_renderbuffer((2 * W, H),
                                                                                samples=self.samples))
        self.color = tuple(float(c) for c in color)
        self.shading = bool(shading)
        self.near, self.far = float(near), float(far)
        self.vao = None
        self.tf_vao = None
        self.n_vertices = 0
        self.model = "none"
        self._wtex = None
        self._upload_depth(np.zeros((2, 2), np.float32))
        self._set_common()
        self.set_model("none")

    # -- state -----------------------------------------------------------------------------------------------
    def _set(self, name: str, value, progs=None) -> None:
        for prog in progs or (self.prog, self.tf_prog):
            if name in prog:
                u = prog[name]
                if isinstance(value, np.ndarray):
                    u.write(np.ascontiguousarray(value,
                                                 dtype=np.int32 if value.dtype.kind in "ib" else np.float32)
                            .tobytes())
                else:
                    u.value = value

    def _set_common(self) -> None:
        P = self.projector
        self._set("u_proj", tuple(P.position))
        self._set("u_ro", tuple(self.screen_point))
        self._set("u_no", tuple(self.screen_normal))
        self._set("u_min_cos", self.min_cos)
        self._set("u_Kp", np.asarray(P.K, dtype=np.float32).T.copy())   # GLSL mat3 is column-major
        self._set("u_Rp", np.asarray(P.R, dtype=np.float32).T.copy())
        self._set("u_size", (float(P.width), float(P.height)))
        self._set("u_D", self.distortion.astype(np.float32))
        self._set("u_distort", int(bool(np.any(self.distortion != 0.0))))
        self._set("u_near", self.near)
        self._set("u_far", self.far)
        self._set("u_color", self.color, (self.prog,))
        self._set("u_shading", int(self.shading), (self.prog,))
        self._set("u_wtex", DEPTH_UNIT)

    def set_mesh(self, vertices, faces, normals=None) -> None:
        """Upload a mesh: ``vertices`` (N, 3) m, ``faces`` (M, 3) int indices < N, ``normals`` (N, 3) or None
        (computed). Raises ``ValueError`` for bad shapes, NaN or out-of-range indices."""
        v = np.asarray(vertices, dtype=np.float32)
        f = np.asarray(faces)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0 or not np.all(np.isfinite(v)):
            raise ValueError(f"vertices must be a finite non-empty (N, 3) array, got shape {v.shape}")
        if (f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu"
            or (f.size and (f.min() < 0 or f.max() >= len(v)))):
            raise ValueError(f"faces must be (M, 3) int indices in [0, {len(v)}), got shape {f.shape}")
        n = vertex_normals(v, f) if normals is None else np.asarray(normals, dtype=np.float32)
        data = np.hstack([v, n]).astype(np.float32)
        ctx = self.ctx
        for obj in (self.vao, self.tf_vao):
            if obj is not None:
                obj.release()
        if getattr(self, "_vbo", None) is not None:
            self._vbo.release()
            self._ibo.release()
        self._vbo = ctx.buffer(data.tobytes())
        self._ibo = ctx.buffer(f.astype(np.int32).tobytes())
        self.vao = ctx.vertex_array(self.prog, [(self._vbo, "3f 3f", "in_pos", "in_normal")], self._ibo)
        self.tf_vao = ctx.vertex_array(self.tf_prog, [(self._vbo, "3f 3x4", "in_pos")])
        self.n_vertices = len(v)

    def set_model(self, model: str, sheet: SheetSurface | None = None) -> None:
        """Choose the correction model and the sheet it corrects for.

        ``model`` ∈ {"none", "flat", "four_triangle", "fine"}; ``sheet`` the (measured) sheet (required
        unless "none"). "fine" on a sheet without a membrane falls back to "flat" (identical result); its
        membrane goes to the shader as a depth table (a texture): a
        :class:`~flexsheet.model.sheet_model.SampledShape` as it is, any other shape sampled into one every
        :data:`~flexsheet.model.sheet_model.GRID_STEP` (so the numpy twin of the drawing is the correction on
        that sampled shape). Raises ``ValueError`` naming the argument."""
        if model not in MODE_IDS:
            raise ValueError(f"model must be one of {sorted(MODE_IDS)}, got {model!r}")
        if model != "none" and not isinstance(sheet, SheetSurface):
            raise ValueError(f"model {model!r} needs a SheetSurface sheet, got {sheet!r}")
        if model == "fine" and sheet.membrane is None:
            model = "flat"
        mode = MODE_IDS[model]
        if model == "flat":
            self._set("u_rs", tuple(sheet.origin))
            self._set("u_ns", tuple(sheet.normal))
        elif model == "four_triangle":
            q, cs, nrm, usable, _ = fan_triangles(sheet.pushed_point, sheet.corners, self.projector.position)
            self._set("u_q", tuple(q))
            self._set("u_c", cs.astype(np.float32))
            self._set("u_tn", nrm.astype(np.float32))
            self._set("u_usable", usable.astype(np.int32))
        elif model == "fine":
            m = sampled(sheet.membrane)
            self._set("u_o", tuple(sheet.origin))
            self._set("u_n", tuple(sheet.normal))
            self._set("u_eu", tuple(sheet.axis_u))
            self._set("u_ev", tuple(sheet.axis_v))
            self._set("u_a", float(m.half_span))
            self._set("u_b", float(m.half_width))
            self._upload_depth(m.w)
        self._set("u_mode", mode)
        self.model = model

    def _upload_depth(self, w: np.ndarray) -> None:
        """The depth table (nu, nv) float32 into the R32F texture (texel (i, j) = w[i, j]), reused while its
        size stays."""
        nu, nv = w.shape
        if self._wtex is None or self._wtex.size != (nu, nv):
            if self._wtex is not None:
                self._wtex.release()
            self._wtex = self.ctx.texture((nu, nv), 1, dtype="f4")
            self._wtex.filter = (self.moderngl.NEAREST, self.moderngl.NEAREST)
        self._wtex.write(np.ascontiguousarray(w.T, dtype=np.float32).tobytes())
        self._set("u_wn", (int(nu), int(nv)))

    # -- drawing ---------------------------------------------------------------------------------------------
    def render_pair(self, eyes=None) -> None:
        """Draw the left (x ∈ [0, W)) and right (x ∈ [W, 2W)) images into the framebuffer; waits for the
        GPU."""
        if self.vao is None:
            raise RuntimeError("set_mesh() first")
        W, H = self.projector.width, self.projector.height
        target = self.msaa or self.fbo
        target.use()
        self._wtex.use(location=DEPTH_UNIT)
        self.ctx.enable(self.moderngl.DEPTH_TEST)
        target.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        for i, e in enumerate(eyes if eyes is not None else self.eyes):
            target.viewport = (i * W, 0, W, H)
            self._set("u_eye", tuple(float(x) for x in e))
            self.vao.render(self.moderngl.TRIANGLES)
        if self.msaa is not None:
            self.ctx.copy_framebuffer(self.fbo, self.msaa)
        self.ctx.finish()

    def show_image(self, image: np.ndarray) -> None:
        """Put ``image`` (H, W, 3) uint8 RGB, top row first, the projector's size, in both eyes' halves of the
        frame instead of a rendered pair (registration patterns). Raises ``ValueError`` for another shape."""
        W, H = self.projector.width, self.projector.height
        img = np.asarray(image)
        if img.shape != (H, W, 3) or img.dtype != np.uint8:
            raise ValueError(f"image must be ({H}, {W}, 3) uint8, got {img.shape} {img.dtype}")
        pair = np.ascontiguousarray(np.concatenate([img, img], axis=1)[::-1])
        self.fbo.color_attachments[0].write(pair.tobytes())

    def read_pair(self, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(left, right) uint8 RGB images (h, w, 3), top row first, downscaled by ``scale`` ∈ (0, 1]
        (area)."""
        if not (0.0 < scale <= 1.0):
            raise ValueError(f"scale must be in (0, 1], got {scale!r}")
        W, H = self.projector.width, self.projector.height
        img = np.frombuffer(self.fbo.read(components=3), dtype=np.uint8).reshape(H, 2 * W, 3)[::-1]
        left, right = img[:, :W], img[:, W:]
        if scale < 1.0:
            import cv2

            size = (max(1, round(W * scale)), max(1, round(H * scale)))
            left = cv2.resize(left, size, interpolation=cv2.INTER_AREA)
            right = cv2.resize(right, size, interpolation=cv2.INTER_AREA)
        return np.ascontiguousarray(left), np.ascontiguousarray(right)

    def render_single(self, eye) -> np.ndarray:
        """Render one eye's image (H, W) float in [0, 1] (mean of RGB), for measurements."""
        self.render_pair(eyes=[eye])
        left, _ = self.read_pair()
        return left.mean(axis=2) / 255.0

    def transform(self, eye) -> tuple[np.ndarray, np.ndarray]:
        """Run the vertex shader's correction on the uploaded vertices for ``eye`` (transform feedback).

        Returns (corrected (N, 3) float32 m, valid (N,) bool) as the shader computed them."""
        if self.tf_vao is None:
            raise RuntimeError("set_mesh() first")
        data = self._feedback(eye)
        return data[:, :3].copy(), data[:, 3] > 0.5

    def projector_pixels(self, eye) -> np.ndarray:
        """The projector pixel (N, 2) float32 (x right, y down; pixel centres at integers) at which the
        shader draws each uploaded vertex for ``eye`` (transform feedback): K_p·distort(R^T (X − P)) of the
        vertex's screen point X, as ``cv2.projectPoints`` would give it."""
        if self.tf_vao is None:
            raise RuntimeError("set_mesh() first")
        return self._feedback(eye)[:, 4:6].copy()

    def _feedback(self, eye) -> np.ndarray:
        self._set("u_eye", tuple(float(x) for x in eye), (self.tf_prog,))
        self.fbo.use()                    # EGL standalone contexts need a bound framebuffer for any draw
        self._wtex.use(location=DEPTH_UNIT)
        out = self.ctx.buffer(reserve=self.n_vertices * 24)
        self.tf_vao.transform(out, mode=self.moderngl.POINTS, vertices=self.n_vertices)
        data = np.frombuffer(out.read(), dtype=np.float32).reshape(-1, 6)
        out.release()
        return data

    @property
    def texture(self):
        """The resolved colour texture (2W × H, RGB; left eye in x ∈ [0, W), right in [W, 2W), bottom row
        first as GL stores it): what :meth:`read_pair` reads and what a window output presents."""
        return self.fbo.color_attachments[0]

    def release(self) -> None:
        """Free the GL objects, and the context if this renderer created it (a window's context stays)."""
        if self.owns_ctx:
            self.ctx.release()
            return
        objs = [self.vao, self.tf_vao, getattr(self, "_vbo", None), getattr(self, "_ibo", None), self.prog,
                self.tf_prog, self.fbo, self.msaa, self._wtex]
        for fb in (self.fbo, self.msaa):
            if fb is not None:
                objs += list(fb.color_attachments) + [fb.depth_attachment]
        for obj in objs:
            if obj is not None:
                obj.release()

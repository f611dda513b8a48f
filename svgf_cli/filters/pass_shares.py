"""The light passes' shares of a signal, accumulated over time (``filters.composable``).

A signal that holds several light passes (Cycles' ``specular``: glossy and transmission,
direct and indirect) is split among them by each pass's stored light averaged over the
pixels that have its colour (a 9x9 tent). One frame's 1-spp passes make that average noisy
and make it flicker from frame to frame, so each pass's average is blended with last frame's at the
pixel the motion vectors point to, as the colour's history is (``filters.shares.
blend_previous``): the blend factor is the colour filter's for that signal and pixel,
``max(alpha, 1 / h)``, so where its history was rejected or cut short by anti-lag (a light
switching on changes the passes' shares too) this frame's average counts alone.
"""

from __future__ import annotations

import numpy as np

from svgf_cli.filters.shares import blend_previous

F32 = np.float32


class PassShares:
    """Last frame's averaged stored light of each light pass (by its channels: a pass black
    in a frame is not among its passes, so an index would name another pass the next
    frame) and last frame's mesh ids; :meth:`blend` folds them into this frame's, in
    place, :meth:`advance` keeps this frame's for the next."""

    def __init__(self) -> None:
        self.previous: dict[tuple[str, ...], np.ndarray] = {}
        self.previous_mesh: np.ndarray | None = None
        self._current: dict[tuple[str, ...], np.ndarray] = {}

    def reset(self) -> None:
        """Forget the history (a new shot, or another history loaded for the colour)."""
        self.previous.clear()
        self._current.clear()
        self.previous_mesh = None

    def blend(self, key: tuple[str, ...], mean: np.ndarray, spread: np.ndarray,
              motion: np.ndarray, mesh_id: np.ndarray, length: np.ndarray | None,
              alpha: float) -> None:
        """Pass ``key``'s average ``mean`` (3, H, W) blended in place with its own last
        frame's, that clamped to ``mean +- spread`` (none: as it is; ``length`` None: no
        history for its signal), and kept. Last frame's is let go once read: a pass is
        blended once a frame, so the passes' two frames of averages are not held at once."""
        previous = self.previous.pop(key, None)
        if (previous is not None and length is not None and self.previous_mesh is not None
                and previous.shape == mean.shape):
            blend_previous(mean, spread, previous, np.ascontiguousarray(motion, dtype=F32),
                           np.ascontiguousarray(mesh_id), self.previous_mesh,
                           np.ascontiguousarray(length, dtype=F32), float(alpha))
        self._current[key] = mean.copy()

    def advance(self, mesh_id: np.ndarray) -> None:
        """This frame's averages become last frame's (a pass not averaged this frame, black
        in it, has none)."""
        self.previous, self._current = self._current, {}
        self.previous_mesh = np.ascontiguousarray(mesh_id).copy()

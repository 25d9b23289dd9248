"""The renderer node's image services (:class:`ImageServices`, a part of
:class:`nodes.renderer.node.RendererNode`): ``show_image`` draws an image file (registration patterns) in both
eyes instead of the scene, ``clear_image`` the scene again; each is latched on ``/projector/image``."""

from __future__ import annotations

import cv2
import numpy as np

from messages import ProjectorImage

__all__ = ["ImageServices"]


class ImageServices:
    """The image half of the renderer node; it uses the node's ``projector``, ``image_pub`` and
    ``_request``."""

    def srv_show_image(self, args: dict) -> dict:
        """``{path}``: show an image file (any size: scaled to the projector's, nearest neighbour for
        patterns) in both eyes instead of the scene, until ``clear_image``; latched on ``/projector/image``.
        Returns the path, the projector's size and the stamp it was shown at (s, the graph's clock)."""
        path = args.get("path")
        if not isinstance(path, str) or not path:
            raise ValueError(f"show_image needs 'path' (an image file), got {path!r}")
        img = cv2.imread(path, cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"cannot read an image from {path!r}")
        W, H = self.projector.width, self.projector.height
        if img.shape[:2] != (H, W):
            img = cv2.resize(img, (W, H), interpolation=cv2.INTER_NEAREST)
        self._image = img[:, :, ::-1].copy()        # BGR → RGB
        self._request()
        header = self.image_pub.header("projector")
        self.image_pub.publish(ProjectorImage(header=header, image=cv2.cvtColor(img, cv2.COLOR_BGR2GRAY),
                                              showing=True, name=path))
        return {"path": path, "size": [W, H], "stamp": header.stamp}

    def srv_clear_image(self, args: dict) -> str:
        self._image = None
        self._request()
        self.image_pub.publish(ProjectorImage(header=self.image_pub.header("projector"),
                                              image=np.zeros((0, 0), np.uint8), showing=False))
        return "drawing the scene"

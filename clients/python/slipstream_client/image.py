"""Camera frames as numpy arrays (numpy is needed only by this module)."""

from typing import Any, Dict, Tuple

from .wire import WireError, decode


def frame_array(payload: bytes) -> Tuple[Dict[str, int], Dict[str, Any], Any]:
    """Decodes a camera/front payload into (header, frame, pixels).

    pixels is a (height, width, 3) uint8 RGB array. For raw (Rgb8) frames it is a read-only
    view of `payload`: no pixel is copied after the bytes left Zenoh (call .copy() to keep or
    modify it). JPEG and PNG frames are decoded with OpenCV when installed, else Pillow.
    `frame` is the decoded CameraFrame without its data."""
    import numpy as np

    _, header, frame = decode(payload, expected="CameraFrame", copy=False)
    data = frame.pop("data")
    h, w = frame["height"], frame["width"]
    if frame["encoding"] == "Rgb8":
        return header, frame, np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)
    try:
        import cv2

        bgr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise WireError(f"{frame['encoding']} frame does not decode")
        pixels = bgr[:, :, ::-1]
    except ImportError:
        try:
            import io

            from PIL import Image
        except ImportError:
            raise RuntimeError(
                f"{frame['encoding']} frames need OpenCV or Pillow: pip install opencv-python (or pillow), "
                "or set camera.encoding to \"raw\" in config/slipstream.json5"
            ) from None
        pixels = np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))
    if pixels.shape != (h, w, 3):
        raise WireError(f"frame says {w}x{h} but its image is {pixels.shape[1]}x{pixels.shape[0]}")
    return header, frame, pixels

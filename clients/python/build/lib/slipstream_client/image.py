"""Camera frames as numpy arrays (numpy is needed only by this module)."""

from typing import Any, Dict, Tuple

from .wire import WireError, decode


def frame_array(payload: bytes) -> Tuple[Dict[str, int], Dict[str, Any], Any]:
    """Decodes a camera/front payload into (header, frame, pixels).

    pixels is a (height, width, 3) uint8 RGB array. For raw (Rgb8) frames it is a read-only
    view of `payload`: no pixel is copied after the bytes left Zenoh (call .copy() to keep or
    modify it). Lz4 frames are expanded with the `lz4` package (extra `[lz4]`); JPEG and PNG
    frames are decoded with OpenCV when installed, else Pillow.
    `frame` is the decoded CameraFrame without its data."""
    import numpy as np

    _, header, frame = decode(payload, expected="CameraFrame", copy=False)
    data = frame.pop("data")
    h, w = frame["height"], frame["width"]
    if frame["encoding"] == "Rgb8":
        return header, frame, np.frombuffer(data, dtype=np.uint8).reshape(h, w, 3)
    if frame["encoding"] == "Lz4":
        return header, frame, np.frombuffer(lz4_pixels(data, w, h), dtype=np.uint8).reshape(h, w, 3)
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


def lz4_pixels(data: bytes, width: int, height: int) -> bytes:
    """An Lz4 frame's Rgb8 bytes: its LZ4 block expanded into exactly width x height x 3 bytes
    (the size the frame states; the wire decoder has already refused blocks too short for it)."""
    try:
        import lz4.block
    except ImportError:
        raise RuntimeError("Lz4 frames need the lz4 package: pip install 'slipstream-zenoh[lz4]' (or lz4)") from None
    size = width * height * 3
    try:
        rgb = lz4.block.decompress(bytes(data), uncompressed_size=size)
    except lz4.block.LZ4BlockError as e:
        raise WireError(f"Lz4 frame does not decode: {e}") from None
    if len(rgb) != size:
        raise WireError(f"Lz4 frame expands to {len(rgb)} bytes, {width}x{height} Rgb8 is {size}")
    return rgb

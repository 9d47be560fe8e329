"""Reading video frames with their own timestamps, and reading ROI/mask arguments.

Every frame's time comes from the container (``CAP_PROP_POS_MSEC``), never
from the nominal frame rate: real cameras drop and delay frames, and the
nominal rate of a file is often rounded. Only when a container carries no
timestamps at all (every ``POS_MSEC`` is 0) does the reader fall back to the
nominal rate, and says so (``Frames.timestamps_source``).
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from labkit.errors import InputError


@dataclass
class VideoInfo:
    """What the container says about a video (nominal values, for the record only)."""

    path: str
    width: int
    height: int
    frame_count: int
    fps_nominal: float
    fourcc: str
    raw_jpeg: bool = False   # Motion-JPEG read as packets and decoded straight to grey
    undecodable: int = 0     # frames skipped because they did not decode
    count_exact: bool = False  # frame_count counted from the packets (not the container's estimate)
    timestamps_from: str = "container"   # "container", or (declared) "csv" / "fps"
    bayer: str | None = None   # raw Bayer pattern (RGGB, BGGR, GRBG, GBRG) demosaiced to grey
    gain: float | None = None  # deeper than 8 bits: frames scaled by this to float32 (the tray ~200), not cut
    luma: bool = False         # FFmpeg hands over the decoded luma plane (no colour conversion at all)
    times: np.ndarray | None = None   # declared frame times (a CSV) that replace a video's own
    fps_declared: float | None = None  # a declared rate that replaces a video's own times (frame k at k / rate)


def open_video(path: str | Path, *, grey: bool = True):
    """Open a video with OpenCV's FFmpeg backend; InputError if missing, unreadable or empty.

    With ``grey`` (the tracker), :func:`iter_frames` yields grey frames; else BGR.

    Returns ``(capture, VideoInfo)``.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise InputError("no such video file", file=path)
    # OpenCV's own warning on an unreadable file would precede our one-line message: silence it
    log = cv2.utils.logging
    level = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_ERROR)
    try:
        cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    finally:
        log.setLogLevel(level)
    if not cap.isOpened():
        cap.release()
        raise InputError("not a readable video (OpenCV/FFmpeg cannot open it)", file=path,
                         expected="a video file such as .avi/.mkv/.mp4")
    code = int(cap.get(cv2.CAP_PROP_FOURCC))
    fourcc = "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).strip("\x00")
    info = VideoInfo(str(path), int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)),
                     int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), float(cap.get(cv2.CAP_PROP_FPS) or 0.0), fourcc)
    if fourcc.upper() == "MJPG" and grey:
        # each Motion-JPEG packet is a JPEG image: decoding only its luma with imdecode is about
        # 3x faster than FFmpeg's decode + BGR conversion + grey conversion, and the container
        # still gives each packet's timestamp
        info.raw_jpeg = bool(cap.set(cv2.CAP_PROP_FORMAT, -1))
    elif grey:
        _try_luma(cap, info)
    if path.suffix.lower() in (".mkv", ".webm", ".mka") or info.frame_count <= 0:
        # Matroska stores no frame count: OpenCV estimates it from the duration and the time
        # base (1967 "frames" for a 60-frame file with a 1 ms base); count the packets instead
        info.frame_count = count_packets(path)
        info.count_exact = True
    return cap, info


def _read(cap, info: VideoInfo):
    """``cap.read()``; OpenCV's per-frame note that it passes a YUV frame's luma plane on is silenced."""
    if not info.luma:
        return cap.read()
    import cv2

    log = cv2.utils.logging
    level = log.getLogLevel()
    log.setLogLevel(log.LOG_LEVEL_ERROR)
    try:
        return cap.read()
    finally:
        log.setLogLevel(level)


def _try_luma(cap, info: VideoInfo) -> None:
    """Ask FFmpeg for frames without colour conversion: a planar YUV frame then arrives as its luma
    plane (H x W), the grey image itself, without the BGR conversion and back. Kept only if the first
    frame comes out so; the capture is rewound either way."""
    import cv2

    if not cap.set(cv2.CAP_PROP_CONVERT_RGB, 0):
        return
    info.luma = True
    ok, frame = _read(cap, info)
    if not (ok and frame is not None and frame.ndim == 2 and frame.shape == (info.height, info.width)):
        info.luma = False
        cap.set(cv2.CAP_PROP_CONVERT_RGB, 1)
    cap.set(cv2.CAP_PROP_POS_FRAMES, 0)


def count_packets(path: str | Path) -> int:
    """The number of video packets (frames) in a file, read without decoding."""
    import cv2

    cap = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
    try:
        cap.set(cv2.CAP_PROP_FORMAT, -1)
        n = 0
        while cap.grab():
            n += 1
        return n
    finally:
        cap.release()


BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
# OpenCV's older names for the same mosaics (named by the second row's second and third pixels)
_BAYER_ALIAS = {"RGGB": "BG", "BGGR": "RG", "GRBG": "GB", "GBRG": "GR"}


def _bayer_code(pattern: str) -> int:
    import cv2

    return int(getattr(cv2, f"COLOR_Bayer{pattern}2GRAY", getattr(cv2, f"COLOR_Bayer{_BAYER_ALIAS[pattern]}2GRAY")))


def detect_bayer(raw: np.ndarray, min_share: float = 0.03) -> str | None:
    """The Bayer pattern of a raw sensor frame, or None when the frame is not a colour mosaic.

    A mosaic shows a 2 x 2 pattern over the whole frame: the four phases' means
    differ by the light's colour (no real scene does that at the pixel pitch).
    The two greens are the diagonal pair closest to each other; red is taken as
    the brighter of the other two (a warm light; for a grey image the choice of
    red or blue moves nothing).
    """
    if raw.ndim != 2 or min(raw.shape) < 8:
        return None
    f = raw[: raw.shape[0] // 2 * 2, : raw.shape[1] // 2 * 2].astype(np.float64)
    p = np.array([f[0::2, 0::2].mean(), f[0::2, 1::2].mean(), f[1::2, 0::2].mean(), f[1::2, 1::2].mean()])
    spread = float(p.max() - p.min())
    if spread < min_share * max(float(p.mean()), 1e-9):
        return None
    if abs(p[1] - p[2]) <= abs(p[0] - p[3]):          # greens at (0,1), (1,0)
        if abs(p[1] - p[2]) > 0.3 * spread:
            return None
        return "RGGB" if p[0] >= p[3] else "BGGR"
    if abs(p[0] - p[3]) > 0.3 * spread:
        return None
    return "GRBG" if p[1] >= p[2] else "GBRG"


def _grey(frame: np.ndarray, info: VideoInfo) -> np.ndarray | None:
    """One decoded frame -> grey at its own depth: 8-bit as uint8, deeper as float32 x ``info.gain``."""
    import cv2

    if info.raw_jpeg:
        return cv2.imdecode(frame.reshape(-1), cv2.IMREAD_GRAYSCALE)
    if info.bayer is not None:
        mosaic = frame[..., 0] if frame.ndim == 3 else frame     # a grey video decodes to 3 equal channels
        g = cv2.cvtColor(np.ascontiguousarray(mosaic), _bayer_code(info.bayer))
    elif frame.ndim == 3:
        g = cv2.cvtColor(frame, cv2.COLOR_BGRA2GRAY if frame.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    else:
        g = frame
    if g.dtype != np.uint8 or info.gain is not None:
        return np.asarray(g, np.float32) * np.float32(info.gain or 1.0)
    return g


def inspect_first_frame(cap, info: VideoInfo, bayer: str = "auto") -> None:
    """Bayer pattern and bit depth from the first frame; the capture is rewound.

    ``bayer``: ``"auto"`` (:func:`detect_bayer`), ``"none"``, or a pattern. A
    frame deeper than 8 bits sets ``info.gain`` so the tray's bright level maps
    to ~200 in float32: a dim 12-bit frame keeps its fractions instead of
    becoming grey levels 0-3.
    """
    key = (bayer or "auto").strip().upper()
    if key not in ("AUTO", "NONE", *BAYER_PATTERNS):
        raise InputError(f"bad Bayer pattern {bayer!r}", key="--bayer",
                         expected="auto, none, " + ", ".join(BAYER_PATTERNS))
    if info.raw_jpeg:
        if key not in ("AUTO", "NONE"):
            raise InputError("a Motion-JPEG video holds no raw Bayer frames", file=info.path, key="--bayer")
        return
    ok, frame = _read(cap, info)
    _rewind(cap, info)
    if not ok or frame is None or frame.size == 0:
        return
    mono = frame.ndim == 2 or (frame.shape[2] >= 3 and np.array_equal(frame[..., 0], frame[..., 1])
                               and np.array_equal(frame[..., 1], frame[..., 2]))
    if key == "AUTO":
        info.bayer = detect_bayer(frame if frame.ndim == 2 else frame[..., 0]) if mono else None
    elif key != "NONE":
        info.bayer = key
    if frame.dtype != np.uint8:
        g = _grey(frame, info)
        if g is not None:
            info.gain = 200.0 / max(float(np.percentile(g, 99)), 1e-9)


def iter_frames(cap, info: VideoInfo) -> Iterator[tuple[np.ndarray, float]]:
    """Yield ``(grey uint8 frame, t_s)`` with each frame's own container timestamp.

    A frame that cannot be decoded (a damaged or truncated file) is skipped
    and counted in ``info.undecodable``: every frame that decodes is kept.
    (Frames from a capture opened with ``grey=False`` are converted to grey too.)"""
    import cv2

    k = 0
    while True:
        ok, frame = _read(cap, info)
        if not ok or frame is None:
            return
        t_ms = cap.get(cv2.CAP_PROP_POS_MSEC)
        if info.times is not None:
            if k >= info.times.size:
                raise InputError(f"the video holds more frames than the {info.times.size} declared times",
                                 file=info.path, key="--timestamps", expected="one time per frame")
            t_ms = 1000.0 * float(info.times[k])
        elif info.fps_declared:
            t_ms = 1000.0 * k / info.fps_declared
        k += 1
        try:
            grey = _grey(frame, info)
        except cv2.error:
            grey = None
        if grey is None or grey.shape != (info.height, info.width):
            info.undecodable += 1
            continue
        yield grey, t_ms / 1000.0


def check_timestamps(t_s: np.ndarray, fps_nominal: float, path: str) -> tuple[np.ndarray, str, np.ndarray]:
    """Validate container timestamps; fall back to the nominal rate only when there are none.

    Returns ``(t_s, source, faulty)``: ``faulty`` marks frames whose timestamp
    does not exceed every earlier one (a camera's duplicated or reordered
    frame); the tracker flags them lost rather than guess their time.
    """
    t_s = np.asarray(t_s, float)
    if t_s.size > 1 and np.all(t_s == t_s[0]):
        if fps_nominal <= 0:
            raise InputError("the video carries no timestamps and no frame rate", file=path)
        return np.arange(t_s.size) / fps_nominal, "nominal_fps", np.zeros(t_s.size, bool)
    faulty = np.zeros(t_s.size, bool)
    if t_s.size > 1:
        faulty[1:] = t_s[1:] <= np.maximum.accumulate(t_s)[:-1]
    if faulty.sum() > t_s.size // 2:
        raise InputError(f"{int(faulty.sum())} of {t_s.size} frame timestamps do not increase", file=path)
    return t_s, "container", faulty


class SpooledFrames:
    """Every frame decoded once, in order, kept to be read as often as needed.

    An inter-frame codec (H.264, MPEG-4) cannot seek without decoding from the
    last key frame, so sampling 15 frames spread over a clip by seeking costs
    several decodings of the whole clip. Spooling decodes each frame once: the
    static scene's samples and the tracking pass then read the spool. Frames
    stay in memory up to ``memory_bytes``; beyond, they go on to a temporary
    file (the operating system's page cache; removed on :meth:`close`).
    """

    def __init__(self, cap, info: VideoInfo, memory_bytes: int = 1 << 30):
        import tempfile

        self.info = info
        self.times: list[float] = []
        self._held: list[np.ndarray] = []
        self._fh = None
        self._on_file = 0
        self.dtype: np.dtype = np.dtype(np.uint8)
        size = 0
        for grey, t in iter_frames(cap, info):
            if not self.times:
                self.dtype = grey.dtype
            self.times.append(t)
            size += grey.nbytes
            if size <= memory_bytes:
                self._held.append(grey)
                continue
            if self._fh is None:
                self._fh = tempfile.TemporaryFile(prefix="labkit-spool-")
            self._fh.write(np.ascontiguousarray(grey, self.dtype).tobytes())
            self._on_file += 1
        self._file_frames: np.ndarray | None = None
        if self._fh is not None:
            self._fh.flush()
            self._file_frames = np.memmap(self._fh, dtype=self.dtype, mode="r",
                                          shape=(self._on_file, info.height, info.width))

    def __len__(self) -> int:
        return len(self.times)

    def _frame(self, k: int) -> np.ndarray:
        if k < len(self._held):
            return self._held[k]
        assert self._file_frames is not None
        return np.asarray(self._file_frames[k - len(self._held)])

    def samples(self, count: int) -> list[np.ndarray]:
        """Up to ``count`` frames spread evenly over the clip."""
        n = len(self)
        if n == 0:
            return []
        idx = np.unique(np.linspace(0, n - 1, min(count, n)).round().astype(int))
        return [self._frame(int(i)) for i in idx]

    def __iter__(self) -> Iterator[tuple[np.ndarray, float]]:
        for k, t in enumerate(self.times):
            yield self._frame(k), t

    def close(self) -> None:
        self._held = []
        self._file_frames = None
        if self._fh is not None:
            self._fh.close()


def spools(info: VideoInfo) -> bool:
    """Whether a source is read through :class:`SpooledFrames`: a decoded video (Motion-JPEG's own
    packets and image files are read where they lie, cheaply)."""
    return not info.raw_jpeg and not info.fourcc.startswith("images/")


def read_sample_frames(cap, info: VideoInfo, count: int) -> list[np.ndarray]:
    """Up to ``count`` grey frames spread over the video (by seeking), then rewind."""
    import cv2

    n = info.frame_count
    out: list[np.ndarray] = []
    if n <= 0:
        return out
    want = np.unique(np.linspace(0, n - 1, min(count, n)).round().astype(int))
    if info.raw_jpeg or info.count_exact:
        # read on through the packets (cheap for Motion-JPEG), decode only those wanted: seeking by
        # frame index is wrong in Matroska (it seeks by time base) and fails on damaged files
        wanted = set(int(i) for i in want)
        k = 0
        while k <= want[-1]:
            if not cap.grab():
                break
            if k in wanted:
                ok, frame = cap.retrieve()
                try:
                    g = _grey(frame, info) if ok and frame is not None else None
                except cv2.error:
                    g = None
                if g is not None and g.shape == (info.height, info.width):
                    out.append(g)
            k += 1
        _rewind(cap, info)
        return out
    for idx in want:
        cap.set(cv2.CAP_PROP_POS_FRAMES, int(idx))
        ok, frame = _read(cap, info)
        if ok and frame is not None:
            g = _grey(frame, info)
            if g is not None:
                out.append(g)
    _rewind(cap, info)
    return out


def _rewind(cap, info: VideoInfo) -> None:
    """Back to the first frame (re-opening where seeking is unreliable)."""
    import cv2

    if isinstance(cap, ImageSequence):
        cap.open()
    elif info.count_exact:
        cap.open(info.path, cv2.CAP_FFMPEG)
        if info.raw_jpeg:
            cap.set(cv2.CAP_PROP_FORMAT, -1)
        if info.luma:
            cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
    else:
        cap.set(cv2.CAP_PROP_POS_FRAMES, 0)


def parse_roi(text: str | tuple | None, width: int, height: int, *, source: str = "--roi") -> tuple[int, int, int, int]:
    """``"x,y,w,h"`` (pixels) -> a tuple inside the frame; InputError otherwise."""
    if text is None:
        return (0, 0, width, height)
    try:
        vals = [int(round(float(v))) for v in (text.split(",") if isinstance(text, str) else text)]
    except ValueError:
        vals = []
    if len(vals) != 4:
        raise InputError(f"bad region of interest {text!r}", key=source, expected="x,y,w,h in pixels")
    x, y, w, h = vals
    if w < 8 or h < 8 or x < 0 or y < 0 or x + w > width or y + h > height:
        raise InputError(f"region of interest {text!r} is not inside the {width}x{height} frame",
                         key=source, expected="x,y,w,h with x+w <= width, y+h <= height, w,h >= 8")
    return (x, y, w, h)


def load_mask(mask, width: int, height: int) -> np.ndarray | None:
    """A mask image path or array (non-zero = search here) -> bool array of the frame's size."""
    if mask is None:
        return None
    if isinstance(mask, (str, Path)):
        import cv2

        img = cv2.imread(str(mask), cv2.IMREAD_GRAYSCALE) if Path(mask).is_file() else None
        if img is None:
            raise InputError("cannot read the mask image", file=mask, expected="a PNG, non-zero = search")
        mask = img
    mask = np.asarray(mask)
    if mask.shape[:2] != (height, width):
        raise InputError(f"mask is {mask.shape[1]}x{mask.shape[0]}", key="mask",
                         expected=f"the video's size {width}x{height}")
    return mask.astype(bool) if mask.ndim == 2 else mask[..., 0].astype(bool)


# ----------------------------------------------------------------------------- image sequences
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")


def sequence_files(source: str | Path) -> list[Path] | None:
    """The frames of an image sequence (a folder, or a ``frame_%05d.png`` pattern), or None for a file."""
    text = str(source)
    p = Path(text)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise InputError("the folder holds no images", file=p, expected=" / ".join(IMAGE_SUFFIXES))
        return files
    if "%" in p.name:
        files = []
        k0 = None
        for k in range(0, 1000000):
            try:
                f = p.parent / (p.name % k)
            except (TypeError, ValueError):
                raise InputError("bad image sequence pattern", file=text, expected="e.g. frame_%05d.png") from None
            if f.is_file():
                files.append(f)
                k0 = k if k0 is None else k0
            elif k0 is not None or k > 1000:
                break          # numbering starts at 0 or 1 (or within the first 1000); ends at the first gap
        if not files:
            raise InputError("no image matches the pattern", file=text, expected="frame_00000.png, ...")
        return files
    return None


def read_timestamps_csv(path: str | Path, files: list[Path] | None) -> np.ndarray:
    """Frame times from a CSV: a ``t_s`` column, matched by a ``file`` column if there is one, else in order.

    ``files`` None (a video): the times in order, their count checked against the frames later."""
    import csv

    path = Path(path)
    try:
        with open(path, newline="") as fh:
            rows = [r for r in csv.reader(line for line in fh if not line.lstrip().startswith("#")) if r]
    except OSError as e:
        raise InputError(f"cannot read the timestamps ({e.strerror})", file=path) from None
    if not rows:
        raise InputError("the timestamps file is empty", file=path, expected="a header with t_s")
    head = [h.strip().lower() for h in rows[0]]
    if "t_s" not in head:
        raise InputError("no t_s column", file=path, key="t_s", expected="a header line with a t_s column (seconds)")
    it = head.index("t_s")
    fi = head.index("file") if "file" in head else None
    times: dict[str, float] = {}
    order: list[float] = []
    for n, r in enumerate(rows[1:], start=2):
        try:
            t = float(r[it])
        except (ValueError, IndexError):
            raise InputError(f"line {n}: {r!r} has no time", file=path, key="t_s", expected="seconds") from None
        order.append(t)
        if fi is not None and fi < len(r):
            times[Path(r[fi].strip()).name] = t
    if files is None:
        return np.asarray(order, float)
    if fi is not None:
        missing = [f.name for f in files if f.name not in times]
        if missing:
            raise InputError(f"no time for {missing[0]} ({len(missing)} frames without one)", file=path,
                             key="file", expected="one row per image file")
        return np.array([times[f.name] for f in files])
    if len(order) != len(files):
        raise InputError(f"{len(order)} times for {len(files)} images", file=path, expected="one time per image")
    return np.asarray(order, float)


class ImageSequence:
    """A folder of images read like a ``cv2.VideoCapture`` (read, grab, retrieve, get, set, release)."""

    def __init__(self, files: list[Path], t_s: np.ndarray):
        self.files = files
        self.t_s = t_s
        self.pos = 0
        self._cur: int | None = None

    def isOpened(self) -> bool:
        return True

    def grab(self) -> bool:
        if self.pos >= len(self.files):
            return False
        self._cur = self.pos
        self.pos += 1
        return True

    def retrieve(self):
        import cv2

        if self._cur is None:
            return False, None
        # as stored: 16-bit and colour kept (converted to grey at depth by iter_frames)
        img = cv2.imread(str(self.files[self._cur]), cv2.IMREAD_UNCHANGED)
        return img is not None, img

    def read(self):
        if not self.grab():
            return False, None
        ok, img = self.retrieve()
        # an unreadable image is a frame that does not decode (skipped and counted by iter_frames)
        return True, img if ok else np.zeros((0, 0), np.uint8)

    def get(self, prop: int) -> float:
        import cv2

        if prop == cv2.CAP_PROP_POS_MSEC:
            return float(self.t_s[self._cur]) * 1000.0 if self._cur is not None else 0.0
        return 0.0

    def set(self, prop: int, value: float) -> bool:
        import cv2

        if prop == cv2.CAP_PROP_POS_FRAMES:
            self.pos, self._cur = int(value), None
            return True
        return False

    def open(self, *args) -> bool:
        self.pos, self._cur = 0, None
        return True

    def release(self) -> None:
        pass


def open_source(source: str | Path, *, fps: float | None = None, timestamps: str | Path | None = None,
                bayer: str = "auto"):
    """A video file or an image sequence -> ``(capture, VideoInfo)``; frames via :func:`iter_frames`.

    An image sequence (a folder, or a pattern such as ``frame_%05d.png``) takes
    its frame times from ``timestamps`` (a CSV with a ``t_s`` column), else
    from a ``timestamps.csv`` beside the images, else from ``fps``; without
    any it is refused (a sequence carries no times of its own). A video file
    takes ``timestamps`` (one ``t_s`` per frame, in order) or ``fps`` in place
    of its container's times when given (a high-speed camera that wrote a
    playback rate); the first frame sets the Bayer pattern and the bit depth
    (:func:`inspect_first_frame`).
    """
    files = sequence_files(source)
    if files is None:
        if not Path(source).exists() and "%" not in str(source):
            raise InputError("no such video file or image folder", file=source)
        cap, info = open_video(source)
        if timestamps is not None:
            info.times = read_timestamps_csv(timestamps, None)
            info.timestamps_from = "csv"
        elif fps is not None:
            if not fps > 0:
                raise InputError(f"bad frame rate {fps}", key="--fps", expected="frames per second > 0")
            info.fps_declared = float(fps)
            info.timestamps_from = "fps"
        inspect_first_frame(cap, info, bayer)
        return cap, info
    cap, info = _open_sequence(source, files, fps, timestamps)
    inspect_first_frame(cap, info, bayer)
    return cap, info


def _open_sequence(source: str | Path, files: list[Path], fps: float | None, timestamps: str | Path | None):
    """An image sequence and its frame times (see :func:`open_source`)."""
    import cv2

    side = Path(timestamps) if timestamps is not None else files[0].parent / "timestamps.csv"
    if timestamps is not None or side.is_file():
        t_s = read_timestamps_csv(side, files)
        how = "csv"
    elif fps is not None and fps > 0:
        t_s = np.arange(len(files)) / fps
        how = "fps"
    else:
        raise InputError("an image sequence carries no frame times", file=source,
                         expected="--fps RATE, or a timestamps.csv (file,t_s) beside the images, or --timestamps CSV")
    first = cv2.imread(str(files[0]), cv2.IMREAD_UNCHANGED)
    if first is None:
        raise InputError("cannot read the first image", file=files[0])
    h, w = first.shape[:2]
    info = VideoInfo(str(source), w, h, len(files), float(fps or 0.0), f"images/{files[0].suffix[1:].lower()}",
                     count_exact=True)
    info.timestamps_from = how
    return ImageSequence(files, np.asarray(t_s, float)), info

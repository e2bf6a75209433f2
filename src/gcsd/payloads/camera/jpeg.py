"""A photo as a real JPEG with EXIF, the tags photogrammetry tools read (Pillow encodes both).

The picture is a plain 640x480 frame whose shade follows the photo number, with the number, time
and position printed on it (a ground-station developer sees which photo is which). EXIF: Make
"gcsd", Model "SimCam", DateTimeOriginal (UTC), FocalLength; GPS IFD: version 2.3, latitude and
longitude as degrees/minutes/seconds rationals with their N/S and E/W refs, altitude above mean
sea level (ref 0 above, 1 below), GPSImgDirection (true, the camera's yaw), GPS time and date
stamps (UTC). Positions are kept to 1e-7 degrees (seconds with a denominator of 10^5: 3 mm).
"""

from __future__ import annotations

import io
import math
import time

from PIL import Image, ImageDraw
from PIL.TiffImagePlugin import IFDRational as Fraction

from gcsd.payloads.camera.camera import Shot
from gcsd.payloads.camera.messages import MODEL, RESOLUTION, VENDOR

TAG_MAKE, TAG_MODEL, TAG_DATETIME, TAG_EXIF_IFD, TAG_GPS_IFD = 0x010F, 0x0110, 0x0132, 0x8769, 0x8825
TAG_DATETIME_ORIGINAL, TAG_FOCAL_LENGTH = 0x9003, 0x920A
GPS_VERSION, GPS_LAT_REF, GPS_LAT, GPS_LON_REF, GPS_LON = 0, 1, 2, 3, 4
GPS_ALT_REF, GPS_ALT, GPS_TIME, GPS_DIR_REF, GPS_DIR, GPS_DATE = 5, 6, 7, 16, 17, 29
SECONDS_DENOMINATOR = 100_000
JPEG_QUALITY = 75


def _dms(deg: float) -> tuple[Fraction, Fraction, Fraction]:
    deg = abs(deg)
    whole = int(deg)
    minutes_f = (deg - whole) * 60
    minutes = int(minutes_f)
    seconds = Fraction(round((minutes_f - minutes) * 60 * SECONDS_DENOMINATOR), SECONDS_DENOMINATOR)
    return Fraction(whole), Fraction(minutes), seconds


def from_dms(dms, ref: str) -> float:
    """Degrees from an EXIF (d, m, s) triple and its ref (for readers and tests)."""
    d, m, s = (float(v) for v in dms)
    value = d + m / 60 + s / 3600
    return -value if ref in ("S", "W") else value


def encode(shot: Shot, wall_s: float, focal_length_mm: float) -> bytes:
    """The JPEG bytes of one photo taken at `wall_s` (Unix time)."""
    p = shot.pose
    shade = 40 + (shot.index * 37) % 160
    image = Image.new("RGB", RESOLUTION, (shade, 120, 255 - shade))
    draw = ImageDraw.Draw(image)
    draw.text((16, 16), f"{shot.filename}  {p.lat:.7f} {p.lon:.7f} {p.alt_amsl_m:.1f} m", fill=(255, 255, 255))
    utc = time.gmtime(wall_s)
    stamp = time.strftime("%Y:%m:%d %H:%M:%S", utc)
    exif = Image.Exif()
    exif[TAG_MAKE] = VENDOR.decode()
    exif[TAG_MODEL] = MODEL.decode()
    exif[TAG_DATETIME] = stamp
    sub = exif.get_ifd(TAG_EXIF_IFD)
    sub[TAG_DATETIME_ORIGINAL] = stamp
    sub[TAG_FOCAL_LENGTH] = Fraction(round(focal_length_mm * 100), 100)
    gps = exif.get_ifd(TAG_GPS_IFD)
    gps[GPS_VERSION] = b"\x02\x03\x00\x00"
    gps[GPS_LAT_REF] = "N" if p.lat >= 0 else "S"
    gps[GPS_LAT] = _dms(p.lat)
    gps[GPS_LON_REF] = "E" if p.lon >= 0 else "W"
    gps[GPS_LON] = _dms(p.lon)
    gps[GPS_ALT_REF] = b"\x00" if p.alt_amsl_m >= 0 else b"\x01"
    gps[GPS_ALT] = Fraction(round(abs(p.alt_amsl_m) * 1000), 1000)
    gps[GPS_DIR_REF] = "T"
    gps[GPS_DIR] = Fraction(round(math.degrees(p.yaw_rad) % 360 * 100), 100)
    gps[GPS_TIME] = (Fraction(utc.tm_hour), Fraction(utc.tm_min), Fraction(utc.tm_sec))
    gps[GPS_DATE] = time.strftime("%Y:%m:%d", utc)
    out = io.BytesIO()
    image.save(out, "JPEG", quality=JPEG_QUALITY, exif=exif.tobytes())
    return out.getvalue()


def read_position(data: bytes) -> tuple[float, float, float]:
    """(lat, lon, alt AMSL) from a JPEG's EXIF GPS tags."""
    with Image.open(io.BytesIO(data)) as image:
        gps = image.getexif().get_ifd(TAG_GPS_IFD)
    alt = float(gps[GPS_ALT]) * (-1 if gps.get(GPS_ALT_REF) in (b"\x01", 1) else 1)
    return from_dms(gps[GPS_LAT], gps[GPS_LAT_REF]), from_dms(gps[GPS_LON], gps[GPS_LON_REF]), alt

#!/usr/bin/python3
"""Writes the generated seed files of the fuzz corpora (tests/fuzz/seeds/, see README.md).

Run from anywhere: /usr/bin/python3 tests/fuzz/seeds/make_seeds.py (needs pydicom, a Debian package).
Deterministic: the same files every run.
"""
import os
import struct
import zlib

import pydicom
from pydicom.dataset import FileDataset, FileMetaDataset
from pydicom.uid import ExplicitVRLittleEndian

HERE = os.path.dirname(os.path.abspath(__file__))


def out(sub, name, data, mode="wb"):
    os.makedirs(os.path.join(HERE, sub), exist_ok=True)
    with open(os.path.join(HERE, sub, name), mode) as f:
        f.write(data)


def gradient(h, w, maxval):  # rows of ints
    return [[(x + 2 * y) * maxval // (w + 2 * h) for x in range(w)] for y in range(h)]


def u8(row):
    return bytes(row)


def u16(row, endian):
    return struct.pack(endian + "%dH" % len(row), *row)


def png(img, bits):
    h, w = len(img), len(img[0])
    raw = b"".join(b"\0" + (u16(r, ">") if bits == 16 else u8(r)) for r in img)
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, bits, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def tiff(img):  # uncompressed 8-bit grey, little endian, one strip
    h, w = len(img), len(img[0])
    data = b"".join(u8(r) for r in img)
    entries = [(256, 3, 1, w), (257, 3, 1, h), (258, 3, 1, 8), (259, 3, 1, 1), (262, 3, 1, 1),
               (273, 4, 1, 8), (277, 3, 1, 1), (278, 3, 1, h), (279, 4, 1, len(data))]
    ifd_offset = 8 + len(data)
    ifd = struct.pack("<H", len(entries)) + b"".join(
        struct.pack("<HHII", *e) for e in entries) + struct.pack("<I", 0)
    return b"II*\0" + struct.pack("<I", ifd_offset) + data + ifd


def bmp(img):  # 8-bit grey palette
    h, w = len(img), len(img[0])
    row = (w + 3) // 4 * 4
    pixels = b"".join(u8(img[r]).ljust(row, b"\0") for r in range(h - 1, -1, -1))
    palette = b"".join(bytes([i, i, i, 0]) for i in range(256))
    off = 14 + 40 + len(palette)
    return (b"BM" + struct.pack("<IHHI", off + len(pixels), 0, 0, off) +
            struct.pack("<IiiHHIIiiII", 40, w, h, 1, 8, 0, len(pixels), 2835, 2835, 256, 0) +
            palette + pixels)


def xa(path, frames, bits):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.12.1"  # XA
    meta.MediaStorageSOPInstanceUID = "1.2.826.0.1.3680043.10.1.%d.%d" % (frames, bits)
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = FileDataset(path, {}, file_meta=meta, preamble=b"\0" * 128)
    ds.SOPClassUID = meta.MediaStorageSOPClassUID
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.Modality = "XA"
    ds.StudyInstanceUID = "1.2.826.0.1.3680043.10.2"
    ds.SeriesInstanceUID = "1.2.826.0.1.3680043.10.3"
    ds.PatientName = "CARMBA^FUZZ"
    ds.DistanceSourceToDetector = "1000"
    ds.DistanceSourceToPatient = "750"
    ds.ImagerPixelSpacing = ["0.5", "0.5"]
    ds.PositionerPrimaryAngle = "10"
    ds.PositionerSecondaryAngle = "-5"
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.Rows, ds.Columns = 12, 16
    ds.BitsAllocated = 16 if bits > 8 else 8
    ds.BitsStored = bits
    ds.HighBit = bits - 1
    ds.PixelRepresentation = 0
    img = gradient(12, 16, (1 << bits) - 1) * frames
    if frames > 1:
        ds.NumberOfFrames = str(frames)
        ds.PositionerPrimaryAngleIncrement = [str(10 * f) for f in range(frames)]
        ds.PositionerSecondaryAngleIncrement = ["0"] * frames
    ds.PixelData = b"".join(u16(r, "<") if bits > 8 else u8(r) for r in img)
    ds.is_little_endian, ds.is_implicit_VR = True, False
    ds.save_as(os.path.join(HERE, path), write_like_original=False)


def main():
    g8 = gradient(12, 16, 255)
    out("image", "gray8.png", png(g8, 8))
    out("image", "gray16.png", png(gradient(12, 16, 65535), 16))
    out("image", "gray8.pgm", b"P5\n16 12\n255\n" + b"".join(u8(r) for r in g8))
    out("image", "gray8.tif", tiff(g8))
    out("image", "gray8.bmp", bmp(g8))
    os.makedirs(os.path.join(HERE, "dicom"), exist_ok=True)
    xa("dicom/xa_1frame_16bit.dcm", 1, 12)
    xa("dicom/xa_2frame_8bit.dcm", 2, 8)
    out("csv", "observations.csv",
        b"# carmba observations\n# grid: circles 2 2 20\n# image_size: 408 408\n"
        b"view,image,point,u_px,v_px\n0,a.pgm,0,101.25,88.5\n0,a.pgm,1,150,88\n"
        b"0,a.pgm,2,101,140\n0,a.pgm,3,150.5,140\n1,b.pgm,0,90,80\n")
    out("csv", "fiducials.csv",
        b"# carmba ct-fiducials\nid,x_mm,y_mm,z_mm,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz\n"
        b"1,0.5,1,2,0.01,0,0,0.01,0,0.02\n2,50,0,1,0.01,0.001,0,0.01,0,0.02\n")
    out("json", "truth_pose.json",
        b'{"views": [{"id": 0, "cam_from_object": {"rvec": [0.1, 0, 0], "t_mm": [0, 0, 1000]}},\n'
        b'           {"id": "10", "rvec": [0, 0.2, 0], "t_mm": [1, 2, 900]}]}\n')
    out("json", "truth_joint.json",
        b'{"camera": {"image_size": [408, 408], "fx": 2000, "fy": 2000, "cx": 204, "cy": 204,\n'
        b'            "distortion": [0, 0, 0, 0, 0]},\n'
        b' "object_views": [{"id": "a", "rvec": [0, 0, 0], "t_mm": [0, 0, 1000]}]}\n')


if __name__ == "__main__":
    main()

"""Small valid files of every format splinecast reads: the starting points of the mutations.

Every seed is one folder holding the files of one volume (header and data) and names its main
file (the path given to ``splinecast``). The volume is tiny (6 x 5 x 4) so that a mutation lands
in a header field often, and every seed of a format with detached data has a raw data file of
exactly :data:`DATA_BYTES` bytes, as has the sentinel file outside every case folder: a header
that were allowed to name the sentinel would be read successfully, so the harness sees it.

Formats whose library is not installed (vtk, zarr, nibabel, ...) are skipped (:func:`available`).
An OME-Zarr store is a folder: its seed's main path is that folder, and the case builder copies
it whole.
"""

from __future__ import annotations

import bz2
import gzip
import importlib.util
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SHAPE = (6, 5, 4)
#: Bytes of the seeds' uint16 raw data, and of the sentinel.
DATA_BYTES = int(np.prod(SHAPE)) * 2
SPACING = (0.5, 0.75, 2.0)
ORIGIN = (-1.0, 2.0, 3.5)


@dataclass(frozen=True)
class Seed:
    """One valid volume in its own folder."""

    fmt: str
    folder: Path
    main: str  # the path given to splinecast, relative to the folder ("." for a DICOM folder)
    value_range: tuple[float, float]

    @property
    def files(self) -> list[Path]:
        return sorted(p for p in self.folder.rglob("*") if p.is_file() or p.is_symlink())


def ramp(dtype: type | np.dtype = np.uint16) -> np.ndarray:
    """Values that differ along every axis (0 .. 119)."""
    i, j, k = np.indices(SHAPE)
    return ((i + 10 * j + 100 * k) % 120).astype(dtype)


# --------------------------------------------------------------------------- makers
def _npy(folder: Path) -> str:
    np.save(folder / "v.npy", ramp())
    return "v.npy"


def _npz(folder: Path) -> str:
    np.savez(folder / "v.npz", data=ramp(), spacing=np.array(SPACING), origin=np.array(ORIGIN))
    return "v.npz"


def _npz_deflate(folder: Path) -> str:
    np.savez_compressed(folder / "v.npz", data=ramp(np.float32), spacing=np.array(SPACING))
    return "v.npz"


def _mhd_text(data_file: str, element: str = "MET_USHORT") -> str:
    return "\n".join([
        "ObjectType = Image", "NDims = 3", "BinaryData = True", "BinaryDataByteOrderMSB = False",
        "CompressedData = False", "TransformMatrix = 1 0 0 0 1 0 0 0 1",
        "Offset = " + " ".join(map(str, ORIGIN)), "ElementSpacing = " + " ".join(map(str, SPACING)),
        "DimSize = " + " ".join(map(str, SHAPE)), f"ElementType = {element}",
        f"ElementDataFile = {data_file}", "",
    ])


def _raw_bytes() -> bytes:
    return ramp().astype("<u2").tobytes(order="F")


def _mhd(folder: Path) -> str:
    (folder / "v.raw").write_bytes(_raw_bytes())
    (folder / "v.mhd").write_text(_mhd_text("v.raw"))
    return "v.mhd"


def _mha(folder: Path) -> str:
    (folder / "v.mha").write_bytes(_mhd_text("LOCAL").encode() + _raw_bytes())
    return "v.mha"


def _nrrd_header(encoding: str, data_file: str | None = None) -> str:
    lines = [
        "NRRD0004", "type: unsigned short", "dimension: 3", "space: left-posterior-superior",
        "sizes: " + " ".join(map(str, SHAPE)),
        "space directions: " + " ".join(
            "(" + ",".join(str(SPACING[a] if b == a else 0.0) for b in range(3)) + ")"
            for a in range(3)
        ),
        "kinds: domain domain domain", "endian: little", f"encoding: {encoding}",
        "space origin: (" + ",".join(map(str, ORIGIN)) + ")",
    ]
    if data_file is not None:
        lines.append(f"data file: {data_file}")
    return "\n".join(lines) + "\n"


def _nhdr(folder: Path) -> str:
    (folder / "v.raw").write_bytes(_raw_bytes())
    (folder / "v.nhdr").write_text(_nrrd_header("raw", "v.raw"))
    return "v.nhdr"


def _nhdr_bzip2(folder: Path) -> str:
    (folder / "v.raw.bz2").write_bytes(bz2.compress(_raw_bytes()))
    (folder / "v.nhdr").write_text(_nrrd_header("bzip2", "v.raw.bz2"))
    return "v.nhdr"


def _nrrd_raw(folder: Path) -> str:
    (folder / "v.nrrd").write_bytes(_nrrd_header("raw").encode() + b"\n" + _raw_bytes())
    return "v.nrrd"


def _nrrd_gzip(folder: Path) -> str:
    body = gzip.compress(_raw_bytes(), mtime=0)
    (folder / "v.nrrd").write_bytes(_nrrd_header("gzip").encode() + b"\n" + body)
    return "v.nrrd"


def _nrrd_text(folder: Path) -> str:
    body = " ".join(str(int(v)) for v in ramp().ravel(order="F")).encode()
    (folder / "v.nrrd").write_bytes(_nrrd_header("text").encode() + b"\n" + body + b"\n")
    return "v.nrrd"


def _nifti_image(dtype: type = np.float32):
    import nibabel as nib

    affine = np.diag([*SPACING, 1.0])
    affine[:3, 3] = ORIGIN
    img = nib.Nifti1Image(ramp(dtype), affine)
    img.header.set_xyzt_units("mm", "sec")
    img.header["scl_slope"] = 2.0
    img.header["scl_inter"] = 1.0
    return img, nib


def _nifti(folder: Path) -> str:
    img, nib = _nifti_image()
    nib.save(img, folder / "v.nii")
    return "v.nii"


def _nifti_gz(folder: Path) -> str:
    img, nib = _nifti_image(np.int16)
    nib.save(img, folder / "v.nii.gz")
    return "v.nii.gz"


def _nifti_pair(folder: Path) -> str:
    img, nib = _nifti_image(np.uint16)
    nib.save(nib.Nifti1Pair(img.dataobj, img.affine, img.header), folder / "v.hdr")
    return "v.hdr"


def dicom_slice(data2d: np.ndarray, position: tuple[float, float, float], series_uid: str,
                number: int):
    """One CT slice of a series (explicit VR little endian), pixel rows = y."""
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid(entropy_srcs=[series_uid, str(number)])
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = CTImageStorage
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.SeriesInstanceUID = series_uid
    ds.Modality = "CT"
    ds.Rows, ds.Columns = data2d.shape[1], data2d.shape[0]
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated = ds.BitsStored = 16
    ds.HighBit = 15
    ds.PixelRepresentation = 0
    ds.PixelSpacing = [SPACING[1], SPACING[0]]
    ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    ds.ImagePositionPatient = list(position)
    ds.SliceThickness = SPACING[2]
    ds.RescaleSlope = 1
    ds.RescaleIntercept = -20
    ds.InstanceNumber = number
    ds.PixelData = np.ascontiguousarray(data2d.T).astype("<u2").tobytes()
    return ds


def _dicom(folder: Path) -> str:
    uid = "1.2.826.0.1.3680043.8.498.1"
    data = ramp()
    for k in range(SHAPE[2]):
        position = (ORIGIN[0], ORIGIN[1], ORIGIN[2] + k * SPACING[2])
        dicom_slice(data[:, :, k], position, uid, k).save_as(
            folder / f"IM{k:04d}", enforce_file_format=True)
    return "."


def _tiff(folder: Path) -> str:
    import tifffile

    stack = np.ascontiguousarray(ramp().transpose(2, 1, 0))  # (z, y, x)
    tifffile.imwrite(folder / "v.tif", stack, imagej=True,
                     resolution=(1 / SPACING[0], 1 / SPACING[1]),
                     metadata={"spacing": SPACING[2], "unit": "um", "axes": "ZYX"})
    return "v.tif"


def _sidecar(folder: Path) -> str:
    (folder / "v.raw").write_bytes(_raw_bytes())
    (folder / "v.json").write_text(json.dumps({
        "shape": list(SHAPE), "dtype": "uint16", "spacing": list(SPACING),
        "origin": list(ORIGIN), "byte_order": "little", "order": "F", "header_bytes": 0,
        "data_file": "v.raw",
    }))
    return "v.json"


def _vti_writer(folder: Path, mode: str, header: str, compressed: bool) -> str:
    """A ``.vti`` written by VTK itself in one of its encodings."""
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    image = vtkImageData()
    image.SetDimensions(*SHAPE)
    image.SetSpacing(*SPACING)
    image.SetOrigin(*ORIGIN)
    values = numpy_to_vtk(np.ascontiguousarray(ramp().transpose(2, 1, 0)).ravel(), deep=True)
    values.SetName("values")
    image.GetPointData().SetScalars(values)
    writer = vtkXMLImageDataWriter()
    writer.SetInputData(image)
    {"binary": writer.SetDataModeToBinary, "ascii": writer.SetDataModeToAscii,
     "appended": writer.SetDataModeToAppended}[mode]()
    writer.SetEncodeAppendedData(mode == "appended-base64")
    if compressed:
        writer.SetCompressorTypeToZLib()
    else:
        writer.SetCompressorTypeToNone()
    (writer.SetHeaderTypeToUInt64 if header == "UInt64" else writer.SetHeaderTypeToUInt32)()
    writer.SetFileName(str(folder / "v.vti"))
    if not writer.Write():
        raise RuntimeError("VTK could not write the seed")
    return "v.vti"


def _vti(folder: Path) -> str:
    """splinecast's own writer: appended raw binary, zlib, 64-bit headers."""
    import splinecast as sc

    sc.write(sc.Volume(ramp(), spacing=SPACING, origin=ORIGIN), folder / "v.vti")
    return "v.vti"


def _vti_base64(folder: Path) -> str:
    """Inline base64 binary, uncompressed, 32-bit headers."""
    return _vti_writer(folder, "binary", "UInt32", compressed=False)


def _vti_raw(folder: Path) -> str:
    """Appended raw binary, uncompressed, 32-bit headers."""
    return _vti_writer(folder, "appended", "UInt32", compressed=False)


def _vtk_legacy(folder: Path) -> str:
    """A hand-written legacy STRUCTURED_POINTS file (binary, big-endian as the format demands)."""
    header = "\n".join([
        "# vtk DataFile Version 3.0", "splinecast fuzz seed", "BINARY", "DATASET STRUCTURED_POINTS",
        "DIMENSIONS " + " ".join(map(str, SHAPE)), "ORIGIN " + " ".join(map(str, ORIGIN)),
        "SPACING " + " ".join(map(str, SPACING)), f"POINT_DATA {int(np.prod(SHAPE))}",
        "SCALARS values unsigned_short 1", "LOOKUP_TABLE default", "",
    ])
    body = ramp().astype(">u2").tobytes(order="F")
    (folder / "v.vtk").write_bytes(header.encode() + body + b"\n")
    return "v.vtk"


def _ome_zarr(folder: Path) -> str:
    """An OME-Zarr 0.5 pyramid (Zarr v3, sharded, zstd) with splinecast's per-brick tables,
    written by splinecast's own builder: two levels of 4-voxel bricks."""
    import splinecast as sc
    from splinecast.multires.store.pyramid import build_pyramid

    build_pyramid(sc.Volume(ramp(), spacing=SPACING, origin=ORIGIN), folder / "v.ome.zarr",
                  brick=4, workers=1, progress=False)
    return "v.ome.zarr"


def _zarr_v2(folder: Path) -> str:
    """An OME-Zarr 0.4 image in Zarr v2 (``.zgroup``, ``.zattrs``, ``.zarray``; blosc and
    zlib chunks of 4 voxels a side) written by zarr-python directly, as other tools do."""
    import zarr

    root = zarr.open_group(str(folder / "v.zarr"), mode="w", zarr_format=2)
    data = np.ascontiguousarray(ramp().transpose(2, 1, 0))  # NGFF z, y, x
    from numcodecs import Blosc, Zlib

    datasets = []
    for level, (block, compressor) in enumerate(((data, Blosc()), (data[::2, ::2, ::2], Zlib()))):
        arr = root.create_array(str(level), shape=block.shape, dtype=block.dtype,
                                chunks=(4, 4, 4), compressors=compressor)
        arr[...] = block
        factor = 2 ** level
        datasets.append({"path": str(level), "coordinateTransformations": [
            {"type": "scale", "scale": [SPACING[2] * factor, SPACING[1] * factor,
                                        SPACING[0] * factor]},
            {"type": "translation", "translation": [ORIGIN[2], ORIGIN[1], ORIGIN[0]]}]})
    root.attrs["multiscales"] = [{
        "version": "0.4", "name": "v",
        "axes": [{"name": a, "type": "space", "unit": "micrometer"} for a in "zyx"],
        "datasets": datasets}]
    return "v.zarr"


def _ngff_levels() -> list[tuple[np.ndarray, list[float], list[float]]]:
    """Two levels in NGFF axis order (z, y, x) with their scale and translation."""
    data = np.ascontiguousarray(ramp().transpose(2, 1, 0))
    spacing = [SPACING[2], SPACING[1], SPACING[0]]
    origin = [ORIGIN[2], ORIGIN[1], ORIGIN[0]]
    return [(block, [s * 2**level for s in spacing], origin)
            for level, block in enumerate((data, data[::2, ::2, ::2]))]


def _multiscales(version: str, datasets: list[tuple[str, list[float], list[float]]]) -> dict:
    return {"version": version, "name": "v", "axes": [
        {"name": a, "type": "space", "unit": "micrometer"} for a in "zyx"],
        "datasets": [{"path": path, "coordinateTransformations": [
            {"type": "scale", "scale": scale}, {"type": "translation", "translation": shift}]}
            for path, scale, shift in datasets]}


def _ome_zarr_py(folder: Path) -> str:
    """OME-Zarr 0.4 laid out as ome-zarr-py writes it: Zarr v2, ``/`` as the chunk key
    separator, zarr's default v2 compressor (blosc lz4 with byte shuffle), chunks of 4."""
    import zarr
    from numcodecs import Blosc

    path = folder / "v.ome.zarr"
    root = zarr.open_group(str(path), mode="w", zarr_format=2)
    datasets = []
    for level, (block, scale, shift) in enumerate(_ngff_levels()):
        arr = root.create_array(str(level), shape=block.shape, dtype=block.dtype,
                                chunks=(4, 4, 4), compressors=Blosc(cname="lz4", clevel=5,
                                                                    shuffle=Blosc.SHUFFLE),
                                chunk_key_encoding={"name": "v2", "separator": "/"})
        arr[...] = block
        datasets.append((str(level), scale, shift))
    root.attrs["multiscales"] = [_multiscales("0.4", datasets)]
    return "v.ome.zarr"


def _ngff_zarr(folder: Path, sharded: bool = False) -> str:
    """OME-Zarr 0.5 laid out as ngff-zarr writes it: Zarr v3, ``attributes.ome``, dimension
    names, zstd (zarr's default v3 codec); ``sharded``: shards of 8 voxels holding chunks of 4
    (blosc zstd, bit shuffle), the index at the end with its crc32c."""
    import zarr
    from zarr.codecs import BloscCodec

    path = folder / "v.ome.zarr"
    root = zarr.open_group(str(path), mode="w", zarr_format=3)
    datasets = []
    for level, (block, scale, shift) in enumerate(_ngff_levels()):
        extra = dict(shards=(8, 8, 8), compressors=BloscCodec(cname="zstd", clevel=5,
                                                               shuffle="bitshuffle")) \
            if sharded else {}
        arr = root.create_array(f"scale{level}", shape=block.shape, dtype=block.dtype,
                                chunks=(4, 4, 4), dimension_names=("z", "y", "x"), **extra)
        arr[...] = block
        datasets.append((f"scale{level}", scale, shift))
    root.attrs["ome"] = {"version": "0.5", "multiscales": [_multiscales("0.5", datasets)]}
    return "v.ome.zarr"


def _ngff_zarr_sharded(folder: Path) -> str:
    return _ngff_zarr(folder, sharded=True)


def _wavelet(folder: Path) -> str:
    """A degree-3 spline-wavelet store (Zarr v3, zstd with checksums, root attribute
    ``splinecast`` of kind ``wavelet``) written by splinecast's builder: two levels of 4-node
    chunks, so coarse, detail and hull arrays all exist."""
    import splinecast as sc
    from splinecast.multires.wavelet.store import build_wavelet_pyramid

    build_wavelet_pyramid(sc.Volume(ramp(), spacing=SPACING, origin=ORIGIN),
                          folder / WAVELET_MAIN, degree=3, levels=2, chunk=4)
    return WAVELET_MAIN


#: The main path of the wavelet seed (the warm-up renders stores of this name in every mode).
WAVELET_MAIN = "v.wavelet.zarr"


#: format -> (maker, module that must exist for the format to be fuzzed).
MAKERS: dict[str, tuple[Callable[[Path], str], str | None]] = {
    "npy": (_npy, None),
    "npz": (_npz, None),
    "npz-deflate": (_npz_deflate, None),
    "mhd": (_mhd, None),
    "mha": (_mha, None),
    "nhdr": (_nhdr, None),
    "nhdr-bzip2": (_nhdr_bzip2, None),
    "nrrd-raw": (_nrrd_raw, None),
    "nrrd-gzip": (_nrrd_gzip, None),
    "nrrd-text": (_nrrd_text, None),
    "nifti": (_nifti, "nibabel"),
    "nifti-gz": (_nifti_gz, "nibabel"),
    "nifti-pair": (_nifti_pair, "nibabel"),
    "dicom": (_dicom, "pydicom"),
    "tiff": (_tiff, "tifffile"),
    "sidecar": (_sidecar, None),
    "vti": (_vti, "vtkmodules"),
    "vti-base64": (_vti_base64, "vtkmodules"),
    "vti-raw": (_vti_raw, "vtkmodules"),
    "vtk-legacy": (_vtk_legacy, "vtkmodules"),
    "ome-zarr": (_ome_zarr, "zarr"),
    "zarr-v2": (_zarr_v2, "zarr"),
    "wavelet": (_wavelet, "zarr"),
    "ome-zarr-py": (_ome_zarr_py, "zarr"),
    "ngff-zarr": (_ngff_zarr, "zarr"),
    "ngff-zarr-sharded": (_ngff_zarr_sharded, "zarr"),
}


def available(fmt: str) -> bool:
    """Whether the reader (and the library the seed maker needs) of ``fmt`` is installed."""
    module = MAKERS[fmt][1]
    if module is None:
        return True
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a missing parent package
        return False


def make_seeds(root: Path, formats: list[str] | None = None) -> dict[str, Seed]:
    """Write one seed folder per available format under ``root``; returns them by format."""
    seeds = {}
    for fmt, (maker, _) in MAKERS.items():
        if (formats and fmt not in formats) or not available(fmt):
            continue
        folder = root / fmt
        folder.mkdir(parents=True, exist_ok=True)
        try:
            main = maker(folder)
        except Exception as exc:  # e.g. no writer for the format yet: skip it, loudly
            print(f"fuzz: no seed for {fmt}: {exc}")
            continue
        import splinecast as sc

        try:  # the seed must be valid: its value range gives the cases' isovalues
            value_range = sc.read(folder / main).value_range
        except sc.SplinecastError as exc:
            print(f"fuzz: the {fmt} seed is not readable ({exc}); format skipped")
            continue
        seeds[fmt] = Seed(fmt, folder, main, value_range)
    return seeds

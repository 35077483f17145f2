"""Writers of the topography formats microbsdf reads, written from the formats' descriptions (not
from microbsdf's C++ readers, which the tests check against them): for simulated surfaces handed to
metrology software (Gwyddion, MountainsMap, the openGPS tools), measured-looking test data, and the
tests.
  X3P  ISO 25178-72: a ZIP (zipfile) with main.xml (ISO 5436-2 schema), bindata/data.bin, an optional
       valid-points bit mask and md5checksum.hex;
  SDF  Surfstand / ISO 25178-71, text (aBCR-1.0) and binary (bBCR-1.0, 81-byte packed header);
  GSF  Gwyddion Simple Field 1.0;
  EXR  OpenEXR 2, uncompressed scanlines, one FLOAT channel "Y" (no EXR module in Debian's Python).
Heights are given in metres as a (ny, nx) numpy array (row j is y, column i is x); NaN marks a point
not measured. Needs numpy (Debian's python3-numpy)."""
import hashlib
import struct
import zipfile

import numpy as np

X3P_TYPES = {"I": np.int16, "L": np.int32, "F": np.float32, "D": np.float64}


def x3p_main_xml(nx, ny, dx, dy, ztype, zinc, zoff, data_link=None, data_list=None, feature="SUR",
                 x_axis_type="I", rotation=None, empty_offset=False, root="ISO5436_2"):
    rotation_xml = "" if rotation is None else "<Rotation>" + "".join(
        f"<r{r + 1}{c + 1}>{rotation[r][c]!r}</r{r + 1}{c + 1}>" for r in range(3) for c in range(3)) + "</Rotation>"
    if data_link is not None:
        record3_data = "<DataLink>" + "".join(f"<{k}>{v}</{k}>" for k, v in data_link) + "</DataLink>"
    else:
        record3_data = "<DataList>" + "".join(f"<Datum>{d}</Datum>" for d in data_list) + "</DataList>"
    xy_offset = "<Offset/>" if empty_offset else "<Offset>0.0</Offset>"
    z_offset = "<Offset/>" if empty_offset else f"<Offset>{zoff!r}</Offset>"
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<p:{root} xmlns:p="http://www.opengps.eu/2008/ISO5436_2">
  <Record1>
    <Revision>ISO5436 - 2000</Revision>
    <FeatureType>{feature}</FeatureType>
    <Axes>
      <CX><AxisType>{x_axis_type}</AxisType><DataType>D</DataType><Increment>{dx!r}</Increment>{xy_offset}</CX>
      <CY><AxisType>I</AxisType><DataType>D</DataType><Increment>{dy!r}</Increment>{xy_offset}</CY>
      <CZ><AxisType>A</AxisType><DataType>{ztype}</DataType><Increment>{zinc!r}</Increment>{z_offset}</CZ>{rotation_xml}
    </Axes>
  </Record1>
  <Record2><Date>2026-11-26T12:00:00+00:00</Date><Creator>microbsdf</Creator>
    <Instrument><Manufacturer>none</Manufacturer><Model>writer</Model><Serial>0</Serial><Version>1</Version></Instrument>
    <CalibrationDate>2026-01-01T00:00:00+00:00</CalibrationDate>
    <ProbingSystem><Type>NonContacting</Type><Identification>test</Identification></ProbingSystem>
    <Comment>written by microbsdf's python/topography_files.py</Comment></Record2>
  <Record3>
    <MatrixDimension><SizeX>{nx}</SizeX><SizeY>{ny}</SizeY><SizeZ>1</SizeZ></MatrixDimension>
    {record3_data}
  </Record3>
  <Record4><ChecksumFile>md5checksum.hex</ChecksumFile></Record4>
</p:{root}>
"""


def write_x3p(path, raw, dx, dy, ztype="D", zinc=1.0, zoff=0.0, valid=None, inline=False, corrupt=None,
              layout=None):
    """raw: the stored values (ny, nx) of ztype; z = zoff + zinc * raw metres. valid: bool (ny, nx)
    written as the valid-points mask. corrupt: None or one of 'xml', 'missing-bin', 'short-bin',
    'main-md5', 'data-md5', 'feature', 'axis', 'rotation' (a damaged or unsupported archive, for the
    error tests). layout: None (ISO 25178-72) or a layout other software writes: 'folder' (every
    member under '<stem>/', as R's x3ptools zips a folder), 'empty-offset' (<Offset/> on every axis,
    i.e. 0), 'root-iso5436' (the root element <ISO5436> without the '_2')."""
    ny, nx = raw.shape
    members = {}
    xml_style = {"empty_offset": layout == "empty-offset", "root": "ISO5436" if layout == "root-iso5436" else "ISO5436_2"}
    if layout == "empty-offset":
        zoff = 0.0
    if inline:
        data_list = ["" if (valid is not None and not valid[j, i]) else repr(float(raw[j, i]))
                     for j in range(ny) for i in range(nx)]
        xml = x3p_main_xml(nx, ny, dx, dy, ztype, zinc, zoff, data_list=data_list, **xml_style)
    else:
        data = np.ascontiguousarray(raw.astype(X3P_TYPES[ztype]).astype("<" + np.dtype(X3P_TYPES[ztype]).str[1:]))
        blob = data.tobytes()  # x fastest, then y
        if corrupt == "short-bin":
            blob = blob[:-3]
        link = [("PointDataLink", "bindata/data.bin"),
                ("MD5ChecksumPointData", hashlib.md5(data.tobytes()).hexdigest() if corrupt != "data-md5"
                 else "0" * 32)]
        if valid is not None:
            bits = np.packbits(valid.reshape(-1).astype(np.uint8), bitorder="little").tobytes()
            link += [("ValidPointsLink", "bindata/valid.bin"), ("MD5ChecksumValidPoints", hashlib.md5(bits).hexdigest())]
            members["bindata/valid.bin"] = bits
        if corrupt != "missing-bin":
            members["bindata/data.bin"] = blob
        c, sn = np.cos(0.1), np.sin(0.1)
        xml = x3p_main_xml(nx, ny, dx, dy, ztype, zinc, zoff, data_link=link,
                           feature="PRF" if corrupt == "feature" else "SUR",
                           x_axis_type="A" if corrupt == "axis" else "I",
                           rotation=[[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]] if corrupt == "rotation" else None,
                           **xml_style)
    if corrupt == "xml":
        xml = xml.replace("</Record1>", "</Recrod1>")
    xml_bytes = xml.encode()
    digest = hashlib.md5(xml_bytes).hexdigest() if corrupt != "main-md5" else "f" * 32
    folder = path.rsplit("/", 1)[-1].rsplit(".", 1)[0] + "/" if layout == "folder" else ""

    def member(name):  # a fixed time stamp: the same surface gives the same bytes
        info = zipfile.ZipInfo(folder + name, date_time=(1980, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        return info

    with zipfile.ZipFile(path, "w") as z:
        if folder:
            z.writestr(zipfile.ZipInfo(folder, date_time=(1980, 1, 1, 0, 0, 0)), b"")
        z.writestr(member("main.xml"), xml_bytes)
        z.writestr(member("md5checksum.hex"), f"{digest} *main.xml\n")
        for name, blob in members.items():
            z.writestr(member(name), blob)


SDF_TYPES = {0: "<u1", 1: "<u2", 2: "<u4", 3: "<f4", 4: "<i1", 5: "<i2", 6: "<i4", 7: "<f8"}


def write_sdf_text(path, raw, xscale, yscale, zscale, datatype=7, truncate=False):
    ny, nx = raw.shape
    lines = ["aBCR-1.0", "ManufacID   = microbsdf", "CreateDate  = 261120261200", "ModDate     = 261120261200",
             f"NumPoints   = {nx}", f"NumProfiles = {ny}", f"Xscale      = {xscale!r}", f"Yscale      = {yscale!r}",
             f"Zscale      = {zscale!r}", "Zresolution = -1", "Compression = 0", f"DataType    = {datatype}",
             "CheckType   = 0", "NumDataSet  = 1", "NanPresent  = 0", "*"]
    values = [repr(float(v)) if datatype in (3, 7) else str(int(v)) for v in raw.reshape(-1)]
    if truncate:
        values = values[:-5]
    for r in range(0, len(values), nx):
        lines.append(" ".join(values[r:r + nx]))
    lines += ["*", "trailer text", "*"]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_sdf_binary(path, raw, xscale, yscale, zscale, datatype=7):
    ny, nx = raw.shape
    header = (b"bBCR-1.0" + b"microbsdf\0" + b"261120261200" + b"261120261200" + struct.pack("<HH", nx, ny)
              + struct.pack("<dddd", xscale, yscale, zscale, -1.0) + bytes([0, datatype, 0]))
    assert len(header) == 81
    with open(path, "wb") as f:
        f.write(header + raw.astype(SDF_TYPES[datatype]).tobytes())


def write_gsf(path, z, xreal, yreal, xy_units="m", z_units="m", drop_units=False):
    ny, nx = z.shape
    head = f"Gwyddion Simple Field 1.0\nXRes = {nx}\nYRes = {ny}\nXReal = {xreal!r}\nYReal = {yreal!r}\n"
    if not drop_units:
        head += f"XYUnits = {xy_units}\nZUnits = {z_units}\n"
    head += "Title = microbsdf test\n"
    b = head.encode()
    b += b"\0" * (4 - len(b) % 4)
    with open(path, "wb") as f:
        f.write(b + z.astype("<f4").tobytes())


def write_exr(path, pixels):
    """One FLOAT channel "Y", uncompressed scanlines, increasing y (OpenEXR file layout, 2.0)."""
    ny, nx = pixels.shape

    def attr(name, type_, value):
        return name.encode() + b"\0" + type_.encode() + b"\0" + struct.pack("<i", len(value)) + value

    header = b"\x76\x2f\x31\x01" + struct.pack("<i", 2)
    header += attr("channels", "chlist", b"Y\0" + struct.pack("<iB3xii", 2, 0, 1, 1) + b"\0")
    header += attr("compression", "compression", b"\0")
    header += attr("dataWindow", "box2i", struct.pack("<iiii", 0, 0, nx - 1, ny - 1))
    header += attr("displayWindow", "box2i", struct.pack("<iiii", 0, 0, nx - 1, ny - 1))
    header += attr("lineOrder", "lineOrder", b"\0")
    header += attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
    header += attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
    header += attr("screenWindowWidth", "float", struct.pack("<f", 1.0))
    header += b"\0"
    start = len(header) + 8 * ny
    lines, offsets = b"", []
    for y in range(ny):
        offsets.append(start + len(lines))
        row = pixels[y].astype("<f4").tobytes()
        lines += struct.pack("<ii", y, len(row)) + row
    with open(path, "wb") as f:
        f.write(header + struct.pack(f"<{ny}Q", *offsets) + lines)

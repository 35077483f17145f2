#include "io/height_map_file.h"

#include <cstdio>
#include <filesystem>

#include "core/error.h"
#include "io/hdf5_handle.h"
#include "io/output_target.h"

namespace mbsdf {

namespace {

void writeAttribute(hid_t obj, const char* name, double v) {
  H5Dataspace space(H5Screate(H5S_SCALAR), "dataspace");
  H5Attribute a(H5Acreate2(obj, name, H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT), name);
  h5check(H5Awrite(a, H5T_NATIVE_DOUBLE, &v), name);
}

void writeAttribute(hid_t obj, const char* name, const std::string& v) {
  H5Datatype type(H5Tcopy(H5T_C_S1), "string type");
  h5check(H5Tset_size(type, v.empty() ? 1 : v.size()), "string size");
  H5Dataspace space(H5Screate(H5S_SCALAR), "dataspace");
  H5Attribute a(H5Acreate2(obj, name, type, space, H5P_DEFAULT, H5P_DEFAULT), name);
  h5check(H5Awrite(a, type, v.empty() ? "" : v.data()), name);
}

}  // namespace

void writeHeightMap(const std::string& path, const Topography& t) {
  checkOutputPath(path);
  const std::string partial = path + ".partial";
  try {
    setUpHdf5();
    H5File file(H5Fcreate(partial.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), "create " + partial);
    const hsize_t dims[2] = {hsize_t(t.ny), hsize_t(t.nx)};
    H5Dataspace space(H5Screate_simple(2, dims, nullptr), "dataspace");
    H5Dataset d(H5Dcreate2(file, "heights_um", H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                "create /heights_um");
    h5check(H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, t.z_um.data()), "write /heights_um");
    writeAttribute(d, "dx_um", t.dx_um);
    writeAttribute(d, "dy_um", t.dy_um);
    writeAttribute(d, "source", t.source);
    d.close("close /heights_um");
    file.close("close " + partial);
  } catch (const std::exception& e) {
    std::remove(partial.c_str());
    throw WriteError(partial + ": " + e.what());
  }
  syncPath(partial);
  std::error_code ec;
  std::filesystem::rename(partial, path, ec);
  if (ec) {
    std::remove(partial.c_str());
    throw WriteError(path + ": cannot rename the written file into place: " + ec.message());
  }
}

}  // namespace mbsdf

// Loaders for explicit microgeometry files: OBJ (tinyobjloader) and PLY (ASCII and binary
// little/big endian, vertex x/y/z + face vertex_indices), and heightfields stored as single-channel
// float EXR images. Every error names the file.
#pragma once
#include <string>

#include "geometry/microgeometry.h"

namespace mbsdf {

// Length unit factor to micrometres for "nm", "um", "mm", "m"; throws InputError for others.
double unitToMicrometres(const std::string& unit, const std::string& where);

// Loads OBJ or PLY by extension. Vertices are scaled by `scale` (to µm) but not moved.
Microgeometry loadMesh(const std::string& path, double scale);

// Reads the first of the channels Y, Z, R, H (or the only channel) of a float EXR image as heights.
// Returns heights (row-major, width x height) and fills width/height.
std::vector<double> loadHeightfieldExr(const std::string& path, int* width, int* height);

}  // namespace mbsdf

// The objects the material preview shows, as triangle meshes with smooth vertex normals, fitted in
// the unit ball about the origin with z up: a sphere, a shader ball (a sphere on a stand on a round
// base, after the test objects of material previews), a square plane (z = 0, normal +z) and any OBJ
// or PLY mesh (normals averaged from the faces around each vertex, weighted by angle).
#pragma once
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "core/vecmath.h"

namespace mbsdf {

struct RenderMesh {
  std::vector<Vec3> positions;
  std::vector<Vec3> normals;  // unit, one per position, pointing out of the object
  std::vector<std::array<uint32_t, 3>> triangles;
};

RenderMesh sphereMesh(const Vec3& centre, double radius, int nLat, int nLon);
RenderMesh shaderBallMesh();
RenderMesh planeMesh(double halfSize);
// "sphere", "ball", "plane", or a path ending in .obj or .ply (InputError naming it otherwise).
RenderMesh shapeByName(const std::string& name);

}  // namespace mbsdf

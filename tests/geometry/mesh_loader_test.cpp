// Mesh and heightfield loaders: round trips and broken files.
#include "geometry/mesh_loader.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <utility>

#include "core/error.h"
#include "geometry/generators.h"
#include "io/exr_image.h"

using namespace mbsdf;

namespace {
std::string tmp(const std::string& name) {
  auto dir = std::filesystem::temp_directory_path() / "microbsdf_tests";
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}
void write(const std::string& path, const std::string& text) {
  std::ofstream(path) << text;
}
std::string errorOf(const std::string& path) {
  try {
    loadMesh(path, 1.0);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(MeshLoader, PlyRoundTripBinary) {
  Microgeometry g =
      makeDomeLattice({.size_um = {10, 10}, .spacing_um = {5, 5}, .radii_um = {2, 2, 2}, .resolution_um = 0.3});
  std::string p = tmp("dome.ply");
  writePly(g, p);
  Microgeometry h = loadMesh(p, 1.0);
  ASSERT_EQ(h.vertices.size(), g.vertices.size());
  ASSERT_EQ(h.triangles.size(), g.triangles.size());
  EXPECT_EQ(h.vertices[17], g.vertices[17]);
  EXPECT_EQ(h.triangles[5], g.triangles[5]);
}

TEST(MeshLoader, AsciiPlyAndObjWithUnits) {
  std::string ply = tmp("quad.ply");
  write(ply,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n");
  Microgeometry a = loadMesh(ply, 1000.0);  // mm -> µm
  EXPECT_EQ(a.triangles.size(), 2u);
  EXPECT_DOUBLE_EQ(a.vertices[2].x, 1000.0);
  std::string obj = tmp("quad.obj");
  write(obj, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
  Microgeometry b = loadMesh(obj, unitToMicrometres("nm", "x"));
  EXPECT_EQ(b.triangles.size(), 2u);
  EXPECT_DOUBLE_EQ(b.vertices[1].x, 1e-3);
  EXPECT_THROW(unitToMicrometres("furlong", "x"), InputError);
}

TEST(MeshLoader, BrokenFilesAreNamed) {
  std::string nanObj = tmp("nan.obj");
  write(nanObj, "v 0 0 0\nv 1 nan 0\nv 1 1 0\nf 1 2 3\n");
  std::string e = errorOf(nanObj);
  EXPECT_NE(e.find("nan.obj:2"), std::string::npos) << e;
  std::string empty = tmp("empty.obj");
  write(empty, "# nothing\n");
  EXPECT_NE(errorOf(empty).find("empty"), std::string::npos);
  std::string bad = tmp("bad.ply");
  write(bad,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n");
  EXPECT_NE(errorOf(bad).find("bad.ply"), std::string::npos);
  std::string nanPly = tmp("nan.ply");
  write(nanPly,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 nan\n1 1 0\n3 0 1 2\n");
  EXPECT_NE(errorOf(nanPly).find("vertex 1"), std::string::npos);
  std::string oob = tmp("oob.ply");
  write(oob,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1 7\n");
  EXPECT_NE(errorOf(oob).find("refers to vertex 7"), std::string::npos);
  EXPECT_NE(errorOf(tmp("missing.ply")).find("not found"), std::string::npos);
  std::string txt = tmp("mesh.stl");
  write(txt, "solid\n");
  EXPECT_NE(errorOf(txt).find("unknown mesh format"), std::string::npos);
}

TEST(MeshLoader, MalformedObjLinesAndShortFacesAreNamed) {
  const std::string quad = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n";
  const std::pair<std::string, std::string> cases[] = {
      {quad + "f 1 2 3\nf 1\n", ":6: a face needs at least 3 vertices"},
      {quad + "f 1 2 3\nf 1 2\n", ":6: a face needs at least 3 vertices"},
      {quad + "f 1 2 3\nf 1 3 5\n", ":6: face vertex 5 does not exist"},
      {quad + "f 1 2 3\nf -1 -2 -9\n", ":6: face vertex -9 does not exist"},
      {"v 1 2\n" + quad + "f 2 3 4\n", ":1: a vertex needs x y z"},
      {quad + "f 1 2 3x\n", ":5: face vertex '3x'"},
      {quad + "l 1 2\nf 1 2 3\n", ":5: unsupported OBJ statement 'l'"},
  };
  for (const auto& [text, message] : cases) {
    const std::string p = tmp("malformed.obj");
    write(p, text);
    EXPECT_NE(errorOf(p).find("malformed.obj" + message), std::string::npos) << text << " -> " << errorOf(p);
  }
  // Accepted: w, vertex colours, relative indices, slashes, groups and comments.
  const std::string ok = tmp("ok.obj");
  write(ok,
        "# patch\no patch\nv -1 -1 0 1\nv 1 -1 0 0.5 0.5 0.5\nv 1 1 0\nv -1 1 0\nvn 0 0 1\ng top\ns off\n"
        "f 1//1 2//1 3//1\n# last\nf -4 -2 -1\n");
  Microgeometry g = loadMesh(ok, 1.0);
  EXPECT_EQ(g.triangles.size(), 2u);
  // A vertex no face uses does not enlarge the footprint.
  write(ok, "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nv 5 5 5 5\nf 1 2 3\nf 1 3 4\n");
  g = loadMesh(ok, 1.0);
  EXPECT_DOUBLE_EQ(g.sizeX, 2.0);
  EXPECT_DOUBLE_EQ(g.sizeY, 2.0);
  // PLY faces with fewer than three indices name the face.
  const std::string ply = tmp("short.ply");
  write(ply,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n"
        "3 0 1 2\n2 0 2\n");
  EXPECT_NE(errorOf(ply).find("short.ply: face 1 has 2 vertex indices"), std::string::npos) << errorOf(ply);
}

// A UTF-8 byte-order mark (written first by editors on Windows) is not part of the first statement:
// the same triangles with and without it, and a malformed line is still named by its number.
TEST(MeshLoader, ObjWithByteOrderMark) {
  const std::string body = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.5\nf 1 2 3\nf 2 4 3\n";
  write(tmp("plain.obj"), body);
  write(tmp("bom.obj"), "\xEF\xBB\xBF" + body);
  const Microgeometry a = loadMesh(tmp("plain.obj"), 1.0), b = loadMesh(tmp("bom.obj"), 1.0);
  ASSERT_EQ(b.triangles.size(), 2u);
  ASSERT_EQ(a.vertices.size(), b.vertices.size());
  for (size_t i = 0; i < a.vertices.size(); ++i) EXPECT_EQ(a.vertices[i], b.vertices[i]);
  for (size_t i = 0; i < a.triangles.size(); ++i) EXPECT_EQ(a.triangles[i], b.triangles[i]);
  write(tmp("bom-bad.obj"), "\xEF\xBB\xBF" + body + "f 1 2\n");
  EXPECT_NE(errorOf(tmp("bom-bad.obj")).find("bom-bad.obj:7"), std::string::npos) << errorOf(tmp("bom-bad.obj"));
}

TEST(HeightfieldLoader, ExrRoundTripAndNaN) {
  const int w = 8, h = 4;
  ExrChannel y{"Y", std::vector<float>(w * h)};
  for (int i = 0; i < w * h; ++i) y.pixels[i] = 0.01f * float(i);
  std::string p = tmp("height.exr");
  writeExr(p, w, h, {y});
  int rw = 0, rh = 0;
  auto v = loadHeightfieldExr(p, &rw, &rh);
  EXPECT_EQ(rw, w);
  EXPECT_EQ(rh, h);
  EXPECT_FLOAT_EQ(float(v[13]), 0.13f);
  y.pixels[5] = std::numeric_limits<float>::quiet_NaN();
  writeExr(p, w, h, {y});
  try {
    loadHeightfieldExr(p, &rw, &rh);
    FAIL() << "NaN height accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("(5, 0)"), std::string::npos) << e.what();
  }
  std::string junk = tmp("junk.exr");
  write(junk, "not an exr");
  EXPECT_THROW(loadHeightfieldExr(junk, &rw, &rh), InputError);
}

// Inputs found by the fuzzers (scripts/fuzz): each must end in an InputError naming the file.
TEST(MeshLoader, FuzzRegressions) {
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(MICROBSDF_SOURCE_DIR) + "/tests/fuzz/regressions/mesh")) {
    std::ifstream in(entry.path(), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_FALSE(bytes.empty());
    // As in fuzz_mesh: the first byte picks the format, the rest is the file.
    std::string path = tmp(std::string("regression") + ((bytes[0] & 1) ? ".ply" : ".obj"));
    write(path, bytes.substr(1));
    std::string e = errorOf(path);
    EXPECT_NE(e.find("regression"), std::string::npos) << entry.path() << ": " << e;
  }
}

// Inputs found by fuzz_heightfield: an InputError naming the file, or a successful read.
TEST(HeightfieldLoader, FuzzRegressions) {
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(MICROBSDF_SOURCE_DIR) + "/tests/fuzz/regressions/heightfield")) {
    std::string path = tmp("regression.exr");
    std::filesystem::copy_file(entry.path(), path, std::filesystem::copy_options::overwrite_existing);
    int w = 0, h = 0;
    try {
      auto v = loadHeightfieldExr(path, &w, &h);
      EXPECT_EQ(v.size(), size_t(w) * h);
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("regression.exr"), std::string::npos) << e.what();
    }
  }
}

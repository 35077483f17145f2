#include "geometry/mesh_loader.h"

#include <tiny_obj_loader.h>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/error.h"

namespace mbsdf {

double unitToMicrometres(const std::string& unit, const std::string& where) {
  if (unit == "um" || unit == "µm") return 1.0;
  if (unit == "nm") return 1e-3;
  if (unit == "mm") return 1e3;
  if (unit == "m") return 1e6;
  throw InputError(where + ": unknown unit '" + unit + "' (use nm, um, mm or m)");
}

namespace {

// Every line of an OBJ file is checked before tinyobjloader reads it (which skips what it cannot
// parse: a truncated face "f 1" would silently leave a hole). Accepted: v (x y z, optionally w or
// an RGB colour), vt, vn, f with at least three vertices whose indices exist (negative ones count
// back), o, g, s, usemtl, mtllib and comment lines. Anything else is an error naming file:line.
void checkObjText(const std::string& path, const std::string& text) {
  std::istringstream f(text);
  std::string line;
  long long vertices = 0;
  auto fail = [&](int lineNo, const std::string& what) {
    throw InputError(path + ":" + std::to_string(lineNo) + ": " + what);
  };
  auto numbers = [&](std::istringstream& ss, int lineNo) {
    std::vector<double> v;
    for (std::string tok; ss >> tok;) {
      char* end = nullptr;
      const double d = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str() || *end != '\0' || !std::isfinite(d)) fail(lineNo, "'" + tok + "' is not a finite number");
      v.push_back(d);
    }
    return v;
  };
  for (int lineNo = 1; std::getline(f, line); ++lineNo) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ss(line);
    std::string kw;
    if (!(ss >> kw) || kw[0] == '#') continue;  // blank or a comment line
    if (kw == "v") {
      const size_t n = numbers(ss, lineNo).size();
      if (n != 3 && n != 4 && n != 6 && n != 7)
        fail(lineNo, "a vertex needs x y z (and optionally w, or r g b): found " + std::to_string(n) + " numbers");
      ++vertices;
    } else if (kw == "vt" || kw == "vn") {
      const size_t n = numbers(ss, lineNo).size();
      if (n < 1 || n > 3) fail(lineNo, kw + " needs 1 to 3 numbers");
    } else if (kw == "f") {
      int count = 0;
      for (std::string ref; ss >> ref; ++count) {
        const std::string index = ref.substr(0, ref.find('/'));
        char* end = nullptr;
        const long long i = std::strtoll(index.c_str(), &end, 10);
        if (index.empty() || *end != '\0' || i == 0)
          fail(lineNo, "face vertex '" + ref + "' is not a vertex index (1-based, or negative from the last vertex)");
        const long long resolved = i > 0 ? i : vertices + i + 1;
        if (resolved < 1 || resolved > vertices)
          fail(lineNo, "face vertex " + index + " does not exist (" + std::to_string(vertices) + " vertices so far)");
      }
      if (count < 3)
        fail(lineNo, "a face needs at least 3 vertices, found " + std::to_string(count) + " (truncated file?)");
    } else if (kw != "o" && kw != "g" && kw != "s" && kw != "usemtl" && kw != "mtllib") {
      fail(lineNo, "unsupported OBJ statement '" + kw + "' (a surface patch uses v, f and optionally vt, vn, o, g, s)");
    }
  }
}

// The file's text without a UTF-8 byte-order mark, which editors on Windows write first and
// tinyobjloader would take as part of the first statement (job files are read the same way).
std::string objText(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open");
  std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (f.bad()) throw InputError(path + ": cannot read");
  if (text.compare(0, 3, "\xEF\xBB\xBF") == 0) text.erase(0, 3);
  return text;
}

Microgeometry loadObj(const std::string& path, double scale) {
  const std::string text = objText(path);
  checkObjText(path, text);
  tinyobj::ObjReader reader;
  tinyobj::ObjReaderConfig cfg;
  cfg.triangulate = true;
  if (!reader.ParseFromString(text, "", cfg)) throw InputError(path + ": cannot read OBJ: " + reader.Error());
  Microgeometry g;
  const auto& v = reader.GetAttrib().vertices;
  for (size_t i = 0; i + 2 < v.size(); i += 3) g.vertices.push_back(Vec3(v[i], v[i + 1], v[i + 2]) * scale);
  for (const auto& shape : reader.GetShapes()) {
    const auto& idx = shape.mesh.indices;
    for (size_t i = 0; i + 2 < idx.size(); i += 3) {
      for (int k = 0; k < 3; ++k)
        if (idx[i + k].vertex_index < 0 || size_t(idx[i + k].vertex_index) >= g.vertices.size())
          throw InputError(path + ": face in shape '" + shape.name + "' refers to a missing vertex");
      g.triangles.push_back(
          {uint32_t(idx[i].vertex_index), uint32_t(idx[i + 1].vertex_index), uint32_t(idx[i + 2].vertex_index)});
    }
  }
  return g;
}

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

PlyType plyType(const std::string& s, const std::string& path) {
  if (s == "char" || s == "int8") return PlyType::Int8;
  if (s == "uchar" || s == "uint8") return PlyType::UInt8;
  if (s == "short" || s == "int16") return PlyType::Int16;
  if (s == "ushort" || s == "uint16") return PlyType::UInt16;
  if (s == "int" || s == "int32") return PlyType::Int32;
  if (s == "uint" || s == "uint32") return PlyType::UInt32;
  if (s == "float" || s == "float32") return PlyType::Float32;
  if (s == "double" || s == "float64") return PlyType::Float64;
  throw InputError(path + ": unknown PLY property type '" + s + "'");
}

size_t plySize(PlyType t) {
  switch (t) {
    case PlyType::Int8:
    case PlyType::UInt8:
      return 1;
    case PlyType::Int16:
    case PlyType::UInt16:
      return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32:
      return 4;
    case PlyType::Float64:
      return 8;
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::Float32;
  bool isList = false;
  PlyType countType = PlyType::UInt8;
};
struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> props;
};

class PlyReader {
 public:
  PlyReader(std::istream& in, bool ascii, bool bigEndian, const std::string& path)
      : in_(in), ascii_(ascii), big_(bigEndian), path_(path) {}
  double read(PlyType t) {
    if (ascii_) {
      std::string tok;
      if (!(in_ >> tok)) throw InputError(path_ + ": unexpected end of PLY data");
      char* end = nullptr;
      double d = std::strtod(tok.c_str(), &end);
      if (end == tok.c_str()) throw InputError(path_ + ": bad number '" + tok + "' in PLY data");
      return d;
    }
    unsigned char b[8];
    size_t n = plySize(t);
    if (!in_.read(reinterpret_cast<char*>(b), n)) throw InputError(path_ + ": unexpected end of PLY data");
    if (big_) std::reverse(b, b + n);
    switch (t) {
      case PlyType::Int8: {
        int8_t v;
        std::memcpy(&v, b, 1);
        return v;
      }
      case PlyType::UInt8:
        return b[0];
      case PlyType::Int16: {
        int16_t v;
        std::memcpy(&v, b, 2);
        return v;
      }
      case PlyType::UInt16: {
        uint16_t v;
        std::memcpy(&v, b, 2);
        return v;
      }
      case PlyType::Int32: {
        int32_t v;
        std::memcpy(&v, b, 4);
        return v;
      }
      case PlyType::UInt32: {
        uint32_t v;
        std::memcpy(&v, b, 4);
        return v;
      }
      case PlyType::Float32: {
        float v;
        std::memcpy(&v, b, 4);
        return v;
      }
      case PlyType::Float64: {
        double v;
        std::memcpy(&v, b, 8);
        return v;
      }
    }
    return 0;
  }

 private:
  std::istream& in_;
  bool ascii_, big_;
  std::string path_;
};

Microgeometry loadPly(const std::string& path, double scale) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path + ": cannot open");
  std::string line;
  std::getline(f, line);
  if (line.rfind("ply", 0) != 0) throw InputError(path + ": not a PLY file (missing 'ply' magic)");
  bool ascii = false, big = false;
  std::vector<PlyElement> elements;
  int lineNo = 1;
  while (std::getline(f, line)) {
    ++lineNo;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream ss(line);
    std::string kw;
    ss >> kw;
    if (kw == "format") {
      std::string fmt;
      ss >> fmt;
      if (fmt == "ascii")
        ascii = true;
      else if (fmt == "binary_big_endian")
        big = true;
      else if (fmt != "binary_little_endian")
        throw InputError(path + ":" + std::to_string(lineNo) + ": unknown PLY format '" + fmt + "'");
    } else if (kw == "element") {
      PlyElement e;
      long long count = -1;
      ss >> e.name >> count;
      // Signed read: "-4" must be an error, not 2^64 − 4 elements (found by fuzz_mesh).
      if (!ss || count < 0 || count > (1ll << 31))
        throw InputError(path + ":" + std::to_string(lineNo) + ": malformed element line (count must be 0 to 2^31)");
      e.count = size_t(count);
      elements.push_back(e);
    } else if (kw == "property") {
      if (elements.empty()) throw InputError(path + ":" + std::to_string(lineNo) + ": property before element");
      PlyProperty p;
      std::string t;
      ss >> t;
      if (t == "list") {
        std::string ct, it;
        ss >> ct >> it >> p.name;
        p.isList = true;
        p.countType = plyType(ct, path);
        p.type = plyType(it, path);
      } else {
        p.type = plyType(t, path);
        ss >> p.name;
      }
      elements.back().props.push_back(p);
    } else if (kw == "end_header") {
      break;
    } else if (kw != "comment" && kw != "obj_info" && !kw.empty()) {
      throw InputError(path + ":" + std::to_string(lineNo) + ": unexpected PLY header keyword '" + kw + "'");
    }
  }
  if (line.rfind("end_header", 0) != 0) throw InputError(path + ": PLY header has no end_header");
  PlyReader r(f, ascii, big, path);
  Microgeometry g;
  for (const auto& e : elements) {
    if (e.props.empty()) continue;  // nothing to read (and no reason to loop 2^31 times)
    if (e.name == "vertex") {
      int xyz = 0;
      for (const auto& p : e.props) xyz += !p.isList && (p.name == "x" || p.name == "y" || p.name == "z");
      if (xyz != 3) throw InputError(path + ": the vertex element needs x, y and z properties");
    }
    for (size_t i = 0; i < e.count; ++i) {
      Vec3 v;
      for (const auto& p : e.props) {
        if (p.isList) {
          // Counts and indices come from the file: check them before converting (a negative or
          // huge double converted to an integer is undefined behaviour; found by fuzz_mesh).
          const double count = r.read(p.countType);
          if (!(count >= 0 && count <= 65536 && count == std::floor(count)))
            throw InputError(path + ": " + e.name + " " + std::to_string(i) + " has an invalid list length");
          const size_t n = size_t(count);
          std::vector<uint32_t> idx(n);
          for (size_t k = 0; k < n; ++k) {
            const double v = r.read(p.type);
            if (!(v >= 0 && v < 4294967296.0 && v == std::floor(v)))
              throw InputError(path + ": " + e.name + " " + std::to_string(i) + " has an invalid vertex index");
            idx[k] = uint32_t(v);
          }
          if (e.name == "face" && (p.name == "vertex_indices" || p.name == "vertex_index")) {
            if (n < 3)
              throw InputError(path + ": face " + std::to_string(i) + " has " + std::to_string(n) +
                               " vertex indices; a face needs at least 3 (truncated file?)");
            for (size_t k = 1; k + 1 < n; ++k) g.triangles.push_back({idx[0], idx[k], idx[k + 1]});
          }
        } else {
          double d = r.read(p.type);
          if (e.name == "vertex") {
            if (p.name == "x")
              v.x = d;
            else if (p.name == "y")
              v.y = d;
            else if (p.name == "z")
              v.z = d;
          }
        }
      }
      if (e.name == "vertex") {
        if (!isFinite(v)) throw InputError(path + ": vertex " + std::to_string(i) + " is not finite (NaN or Inf)");
        g.vertices.push_back(v * scale);
      }
    }
  }
  return g;
}

}  // namespace

Microgeometry loadMesh(const std::string& path, double scale) {
  if (!std::filesystem::exists(path)) throw InputError(path + ": mesh file not found");
  std::string ext = std::filesystem::path(path).extension().string();
  for (auto& c : ext) c = char(std::tolower(c));
  Microgeometry g;
  if (ext == ".obj")
    g = loadObj(path, scale);
  else if (ext == ".ply")
    g = loadPly(path, scale);
  else
    throw InputError(path + ": unknown mesh format '" + ext + "' (use .obj or .ply)");
  // Default footprint: the bounding box in x and y of the vertices the faces use (the job may
  // override it); a vertex no face uses must not enlarge it (indices are checked by validate()).
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  for (const auto& tri : g.triangles)
    for (uint32_t i : tri) {
      if (i >= g.vertices.size()) continue;
      const Vec3& v = g.vertices[i];
      x0 = std::min(x0, v.x);
      x1 = std::max(x1, v.x);
      y0 = std::min(y0, v.y);
      y1 = std::max(y1, v.y);
    }
  g.sizeX = x1 > x0 ? x1 - x0 : 1.0;
  g.sizeY = y1 > y0 ? y1 - y0 : 1.0;
  g.validate(path);
  return g;
}

std::vector<double> loadHeightfieldExr(const std::string& path, int* width, int* height) {
  if (!std::filesystem::exists(path)) throw InputError(path + ": heightfield file not found");
  try {
    Imf::InputFile file(path.c_str());
    Imath::Box2i dw = file.header().dataWindow();
    int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    const Imf::ChannelList& ch = file.header().channels();
    std::string name;
    for (const char* c : {"Y", "Z", "R", "H"})
      if (ch.findChannel(c)) {
        name = c;
        break;
      }
    if (name.empty()) {
      auto it = ch.begin();
      if (it == ch.end()) throw InputError(path + ": EXR has no channels");
      name = it.name();
    }
    // Sizes come from the file: check them before allocating (found by fuzz_heightfield).
    if (w <= 0 || h <= 0 || w > 65536 || h > 65536 || int64_t(w) * h > 100000000)
      throw InputError(path + ": EXR data window of " + std::to_string(w) + " x " + std::to_string(h) +
                       " pixels is empty or too large (at most 65536 per side and 1e8 pixels)");
    std::vector<float> buf(size_t(w) * h);
    Imf::FrameBuffer fb;
    // Slice::Make handles a data window that does not start at (0, 0) without pointer arithmetic
    // outside the buffer (the classic `data - min.x - min.y * w` is undefined behaviour).
    fb.insert(name, Imf::Slice::Make(Imf::FLOAT, buf.data(), dw));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    std::vector<double> out(buf.begin(), buf.end());
    for (size_t i = 0; i < out.size(); ++i)
      if (!std::isfinite(out[i]))
        throw InputError(path + ": height at pixel (" + std::to_string(i % w) + ", " + std::to_string(i / w) +
                         ") is not finite");
    *width = w;
    *height = h;
    return out;
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path + ": cannot read EXR heightfield: " + e.what());
  }
}

}  // namespace mbsdf

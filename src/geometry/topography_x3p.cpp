// ISO 25178-72 "XML file format x3p" (the openGPS container; ISO 5436-2 schema, namespace
// http://www.opengps.eu/2008/ISO5436_2): a ZIP archive holding main.xml and, for binary data,
// bindata/data.bin with an optional valid-points bit mask and an MD5 checksum of main.xml
// (Record4). Only areal data on an incremental grid is a height map here: FeatureType SUR, axes CX
// and CY of type I (increment + offset), CZ of type A with data type I (int16), L (int32), F (float)
// or D (double), z = offset + increment · value, lengths in metres. Points are stored x fastest;
// an invalid point is NaN (F, D) or a 0 bit in the mask (least significant bit first, 1 = valid).
//
// Files written by other software are read where other readers read them, each with a warning that
// names the file: main.xml alone in one folder of the archive, an empty <Offset/> (0), a main.xml
// whose recorded checksum does not match, a root element <ISO5436> without the "_2". A point data or
// valid-points checksum that does not match is damaged data, and an error.
#include <openssl/evp.h>
#include <pugixml.hpp>
#include <zip.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <memory>
#include <optional>

#include "core/error.h"
#include "geometry/topography.h"
#include "geometry/topography_header.h"

namespace mbsdf {
namespace {

static_assert(std::endian::native == std::endian::little, "the X3P binary reader assumes a little-endian host");

struct ZipClose {
  void operator()(zip_t* z) const { zip_discard(z); }
};
struct ZipFileClose {
  void operator()(zip_file_t* f) const { zip_fclose(f); }
};

// The archive's members, read whole; every failure names the archive and the member.
class X3pArchive {
 public:
  explicit X3pArchive(const std::string& path) : path_(path) {
    int code = 0;
    zip_.reset(zip_open(path.c_str(), ZIP_RDONLY, &code));
    if (!zip_) {
      zip_error_t err;
      zip_error_init_with_code(&err, code);
      std::string why = zip_error_strerror(&err);
      zip_error_fini(&err);
      throw InputError(path + ": not a readable X3P (ZIP) archive: " + why);
    }
  }
  // Every member's name, in the archive's order.
  std::vector<std::string> members() const {
    std::vector<std::string> names;
    const zip_int64_t n = zip_get_num_entries(zip_.get(), 0);
    for (zip_int64_t k = 0; k < n; ++k)
      if (const char* name = zip_get_name(zip_.get(), zip_uint64_t(k), 0)) names.emplace_back(name);
    return names;
  }
  // Members named in main.xml are relative to its folder (x3ptools writes `<name>/main.xml` and
  // `<name>/bindata/data.bin`); a name found only at the archive's root is taken from there.
  void setFolder(std::string folder) { folder_ = std::move(folder); }
  std::string resolve(const std::string& member) const {
    if (folder_.empty() || zip_name_locate(zip_.get(), (folder_ + member).c_str(), 0) < 0) return member;
    return folder_ + member;
  }
  std::string read(const std::string& relative, size_t maxBytes) const {
    const std::string member = resolve(relative);
    zip_stat_t st;
    zip_stat_init(&st);
    if (zip_stat(zip_.get(), member.c_str(), 0, &st) != 0)
      throw InputError(path_ + ": the archive has no member '" + member + "'");
    if (!(st.valid & ZIP_STAT_SIZE) || st.size > maxBytes)
      throw InputError(path_ + ": member '" + member + "' is larger than expected (" + std::to_string(st.size) +
                       " bytes, at most " + std::to_string(maxBytes) + ")");
    std::unique_ptr<zip_file_t, ZipFileClose> f(zip_fopen(zip_.get(), member.c_str(), 0));
    if (!f) throw InputError(path_ + ": cannot open member '" + member + "': " + zip_strerror(zip_.get()));
    std::string bytes(size_t(st.size), '\0');
    const zip_int64_t n = zip_fread(f.get(), bytes.data(), st.size);
    if (n < 0 || uint64_t(n) != st.size)
      throw InputError(path_ + ": member '" + member + "' is damaged (" + zip_file_strerror(f.get()) + ")");
    return bytes;
  }

 private:
  std::string path_, folder_;
  std::unique_ptr<zip_t, ZipClose> zip_;
};

// main.xml at the archive's root, as ISO 25178-72 places it, or alone in one folder (archives zipped
// from a folder, as x3ptools writes them): the folder, with a warning, or "" at the root.
std::string mainXmlFolder(const std::string& path, const X3pArchive& zip, std::vector<std::string>& warnings) {
  std::vector<std::string> found;
  for (const std::string& name : zip.members()) {
    if (name == "main.xml") return "";
    if (name.size() > 9 && name.compare(name.size() - 9, 9, "/main.xml") == 0) found.push_back(name);
  }
  if (found.empty()) throw InputError(path + ": the archive has no member 'main.xml'");
  if (found.size() > 1)
    throw InputError(path + ": the archive has no 'main.xml' at its root but " + std::to_string(found.size()) +
                     " in folders ('" + found[0] + "', '" + found[1] + "'): which one is the surface is not known");
  warnings.push_back(path + ": main.xml is in the folder '" + found[0].substr(0, found[0].size() - 8) +
                     "' of the archive, not at its root (ISO 25178-72); read from there");
  return found[0].substr(0, found[0].size() - 8);
}

std::string md5Hex(const std::string& bytes) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  if (EVP_Digest(bytes.data(), bytes.size(), digest, &len, EVP_md5(), nullptr) != 1)
    throw std::runtime_error("MD5 digest failed");
  static const char* hex = "0123456789abcdef";
  std::string out;
  for (unsigned int i = 0; i < len; ++i) {
    out += hex[digest[i] >> 4];
    out += hex[digest[i] & 15];
  }
  return out;
}

std::string lower(std::string s) {
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// main.xml with the line of each element for messages.
struct MainXml {
  const std::string& path;
  const std::string& body;  // main.xml as read
  std::string where(const pugi::xml_node& n) const {
    const ptrdiff_t offset = n.offset_debug();
    const long line = offset < 0 ? 0 : 1 + long(std::count(body.begin(), body.begin() + offset, '\n'));
    return path + ": main.xml line " + std::to_string(line) + ": ";
  }
  pugi::xml_node child(const pugi::xml_node& n, const char* name) const {
    pugi::xml_node c = n.child(name);
    if (!c) throw InputError(where(n) + "<" + n.name() + "> has no <" + name + ">");
    return c;
  }
  std::string text(const pugi::xml_node& n, const char* name) const { return trimmed(child(n, name).child_value()); }
  double number(const pugi::xml_node& n, const char* name, std::optional<double> def = {}) const {
    pugi::xml_node c = n.child(name);
    if (!c && def) return *def;
    const std::string s = text(n, name);
    const std::optional<double> v = parseWhole<double>(s);
    if (!v || !std::isfinite(*v)) throw InputError(where(c) + "<" + name + "> is not a number: '" + s + "'");
    return *v;
  }
  int64_t count(const pugi::xml_node& n, const char* name) const {
    const std::string s = text(n, name);
    const std::optional<int64_t> v = parseWhole<int64_t>(s);
    if (!v || *v < 0) throw InputError(where(child(n, name)) + "<" + name + "> is not a count: '" + s + "'");
    return *v;
  }
};

struct Axis {
  double increment = 1, offset = 0;
  char dataType = 'D';
};

Axis readAxis(const MainXml& xml, const pugi::xml_node& axes, const char* name, const char* wantType,
              std::vector<std::string>& warnings) {
  const pugi::xml_node a = xml.child(axes, name);
  const std::string type = xml.text(a, "AxisType");
  if (type != wantType)
    throw InputError(xml.where(a) + "axis " + name + " has AxisType " + type + "; a height map needs " + wantType +
                     (std::string(wantType) == "I" ? " (a regular grid; resample explicit positions first)" : ""));
  Axis axis;
  axis.increment = xml.number(a, "Increment", 1.0);
  // An empty <Offset/> is written by some instruments' software; other readers take it as 0.
  const pugi::xml_node offset = a.child("Offset");
  if (offset && trimmed(offset.child_value()).empty()) {
    warnings.push_back(xml.where(offset) + "axis " + name + " has an empty <Offset>; taken as 0");
  } else {
    axis.offset = xml.number(a, "Offset", 0.0);
  }
  if (a.child("DataType")) {
    const std::string t = xml.text(a, "DataType");
    if (t.size() != 1 || std::string("ILFD").find(t[0]) == std::string::npos)
      throw InputError(xml.where(a) + "axis " + name + " has DataType '" + t + "' (I, L, F or D)");
    axis.dataType = t[0];
  }
  if (!(axis.increment > 0) && std::string(name) != "CZ")
    throw InputError(xml.where(a) + "axis " + name + " needs a positive Increment");
  if (axis.increment == 0) throw InputError(xml.where(a) + "axis " + name + " has Increment 0");
  return axis;
}

size_t bytesOf(char type) {
  switch (type) {
    case 'I':
      return 2;
    case 'L':
      return 4;
    case 'F':
      return 4;
    default:
      return 8;
  }
}

double rawValue(const char* p, char type) {
  switch (type) {
    case 'I': {
      int16_t v;
      std::memcpy(&v, p, 2);
      return v;
    }
    case 'L': {
      int32_t v;
      std::memcpy(&v, p, 4);
      return v;
    }
    case 'F': {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    default: {
      double v;
      std::memcpy(&v, p, 8);
      return v;
    }
  }
}

void checkMemberMd5(const MainXml& xml, const pugi::xml_node& link, const char* element, const std::string& member,
                    const std::string& bytes) {
  const pugi::xml_node c = link.child(element);
  if (!c) return;
  const std::string want = lower(trimmed(c.child_value()));
  if (want != md5Hex(bytes))
    throw InputError(xml.where(c) + "the MD5 checksum of '" + member + "' does not match its <" + element +
                     "> (the archive is damaged)");
}

// The heights of Record3: a DataLink to binary members or an inline DataList.
void readPoints(const MainXml& xml, const X3pArchive& zip, const pugi::xml_node& record3, const Axis& cz,
                Topography& t) {
  const size_t n = t.size();
  // The grid is allocated once the data is known to hold its points (sizes come from the file).
  auto allocate = [&] {
    t.z_um.assign(n, 0.0);
    t.valid.assign(n, 1);
  };
  auto store = [&](size_t k, double raw) {
    const double z_m = cz.offset + cz.increment * raw;
    if (std::isfinite(z_m))
      t.z_um[k] = z_m * 1e6;
    else
      t.valid[k] = 0;
  };
  if (const pugi::xml_node link = record3.child("DataLink")) {
    const std::string member = xml.text(link, "PointDataLink");
    const size_t expected = n * bytesOf(cz.dataType);
    const std::string data = zip.read(member, expected);
    if (data.size() != expected)
      throw InputError(xml.where(link) + "'" + member + "' holds " + std::to_string(data.size()) + " bytes; " +
                       std::to_string(t.nx) + " x " + std::to_string(t.ny) + " points of type " + cz.dataType +
                       " need " + std::to_string(expected));
    checkMemberMd5(xml, link, "MD5ChecksumPointData", member, data);
    allocate();
    for (size_t k = 0; k < n; ++k) store(k, rawValue(data.data() + k * bytesOf(cz.dataType), cz.dataType));
    if (const pugi::xml_node vl = link.child("ValidPointsLink")) {
      const std::string vmember = trimmed(vl.child_value());
      const std::string mask = zip.read(vmember, (n + 7) / 8);
      if (mask.size() != (n + 7) / 8)
        throw InputError(xml.where(vl) + "'" + vmember + "' holds " + std::to_string(mask.size()) + " bytes; " +
                         std::to_string(n) + " points need " + std::to_string((n + 7) / 8));
      checkMemberMd5(xml, link, "MD5ChecksumValidPoints", vmember, mask);
      for (size_t k = 0; k < n; ++k)
        if (!((static_cast<unsigned char>(mask[k / 8]) >> (k % 8)) & 1u)) t.valid[k] = 0;
    }
  } else if (const pugi::xml_node list = record3.child("DataList")) {
    const size_t count = size_t(std::distance(list.children("Datum").begin(), list.children("Datum").end()));
    if (count != n)
      throw InputError(xml.where(list) + "<DataList> has " + std::to_string(count) + " <Datum>; the matrix has " +
                       std::to_string(n) + " points");
    allocate();
    size_t k = 0;
    for (const pugi::xml_node& d : list.children("Datum")) {
      if (k == n)
        throw InputError(xml.where(d) + "more <Datum> than the " + std::to_string(n) + " points of the matrix");
      std::string s = trimmed(d.child_value());
      if (const auto semi = s.rfind(';'); semi != std::string::npos) s = trimmed(s.substr(semi + 1));
      if (s.empty()) {
        t.valid[k++] = 0;  // an empty Datum is a point not measured
        continue;
      }
      const std::optional<double> v = parseWhole<double>(s);
      if (!v) throw InputError(xml.where(d) + "<Datum> is not a number: '" + s + "'");
      store(k++, *v);
    }
    if (k != n)
      throw InputError(xml.where(list) + "<DataList> has " + std::to_string(k) + " <Datum>; the matrix has " +
                       std::to_string(n) + " points");
  } else {
    throw InputError(xml.where(record3) + "<Record3> has neither <DataLink> nor <DataList>");
  }
}

// Record4: the archive's MD5 checksum of main.xml, in a member written like md5sum's output.
// A mismatch is a warning, as in other readers: main.xml is often edited by hand after the fact, and
// its parse is checked element by element. The point data's own checksum stays an error.
void checkMainChecksum(const MainXml& xml, const X3pArchive& zip, const pugi::xml_node& root,
                       std::vector<std::string>& warnings) {
  const pugi::xml_node record4 = root.child("Record4");
  if (!record4 || !record4.child("ChecksumFile")) return;
  const std::string member = xml.text(record4, "ChecksumFile");
  const std::string sum = zip.read(member, 4096);
  const std::string want = lower(sum.substr(0, std::min<size_t>(32, sum.size())));
  if (want != md5Hex(xml.body))
    warnings.push_back(xml.path + ": the MD5 checksum of main.xml does not match '" + member +
                       "' (main.xml was edited, or the archive is damaged); read all the same");
}

}  // namespace

Topography readX3p(const std::string& path) {
  X3pArchive zip(path);
  Topography t;
  zip.setFolder(mainXmlFolder(path, zip, t.warnings));
  const std::string mainText = zip.read("main.xml", size_t(64) << 20);
  pugi::xml_document doc;
  const pugi::xml_parse_result parsed = doc.load_buffer(mainText.data(), mainText.size());
  const MainXml xml{path, mainText};
  if (!parsed) {
    const long line =
        1 + long(std::count(mainText.begin(),
                            mainText.begin() + std::min<ptrdiff_t>(parsed.offset, ptrdiff_t(mainText.size())), '\n'));
    throw InputError(path + ": main.xml line " + std::to_string(line) + ": " + parsed.description());
  }
  const pugi::xml_node root = doc.document_element();
  const std::string rootName = root.name();
  const auto endsWith = [&](const std::string& tail) {
    return rootName.size() >= tail.size() && rootName.compare(rootName.size() - tail.size(), tail.size(), tail) == 0;
  };
  if (endsWith("ISO5436"))
    t.warnings.push_back(xml.where(root) + "the root element is <" + rootName +
                         ">, not <ISO5436_2>; read as ISO5436_2");
  else if (!endsWith("ISO5436_2"))
    throw InputError(xml.where(root) + "the root element is <" + rootName + ">, not <ISO5436_2>");
  checkMainChecksum(xml, zip, root, t.warnings);

  const pugi::xml_node record1 = xml.child(root, "Record1");
  const std::string feature = xml.text(record1, "FeatureType");
  if (feature != "SUR")
    throw InputError(xml.where(record1) + "FeatureType " + feature + "; only areal surfaces (SUR) are height maps" +
                     (feature == "PRF"   ? " (this is a profile)"
                      : feature == "PCL" ? " (this is a point cloud)"
                                         : ""));
  const pugi::xml_node axes = xml.child(record1, "Axes");
  const Axis cx = readAxis(xml, axes, "CX", "I", t.warnings), cy = readAxis(xml, axes, "CY", "I", t.warnings),
             cz = readAxis(xml, axes, "CZ", "A", t.warnings);
  // An optional rotation turns the stored points into the sample's frame. Taking the heights without
  // it would rotate or tilt the surface silently: only the identity is accepted.
  if (const pugi::xml_node rot = axes.child("Rotation")) {
    for (int r = 1; r <= 3; ++r)
      for (int c = 1; c <= 3; ++c) {
        const std::string name{'r', char('0' + r), char('0' + c)};
        const double v = xml.number(rot, name.c_str(), r == c ? 1.0 : 0.0);
        if (std::abs(v - (r == c ? 1.0 : 0.0)) > 1e-9)
          throw InputError(xml.where(rot) + "the axes carry a rotation (" + name + " = " + std::to_string(v) +
                           "); rotate the data into the sample's frame first (e.g. in Gwyddion) and save it again");
      }
  }

  const pugi::xml_node record3 = xml.child(root, "Record3");
  const pugi::xml_node dims = xml.child(record3, "MatrixDimension");
  const int64_t sx = xml.count(dims, "SizeX"), sy = xml.count(dims, "SizeY"), sz = xml.count(dims, "SizeZ");
  if (sz != 1) throw InputError(xml.where(dims) + "SizeZ is " + std::to_string(sz) + "; a height map has one layer");
  checkTopographySize(path, sx, sy);
  t.nx = int(sx);
  t.ny = int(sy);
  t.dx_um = cx.increment * 1e6;
  t.dy_um = cy.increment * 1e6;
  t.source = path;
  readPoints(xml, zip, record3, cz, t);
  if (t.invalidCount() == 0) t.valid.clear();
  return t;
}

}  // namespace mbsdf

// Reading and writing triangle meshes as PLY files, the format the app writes
// its background and object surfaces in.
//
// write_ply stores positions and normals as float and faces as
// "list uchar int vertex_indices", little-endian binary or ascii. It writes
// to "<path>.tmp" and renames that over `path` only once everything is on
// disk, so a failed write never leaves a half-written file under `path` and
// leaves any earlier file there as it was.
//
// read_ply reads what write_ply writes and the common variants from other
// tools: ascii and either binary byte order, any scalar property types,
// extra properties and elements (ignored), and polygons (fanned into
// triangles). Errors are std::runtime_error naming the file and the problem.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "emfusion/core/math.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/volume/mesh.hpp"

namespace emfusion {

enum class PlyFormat {
  binary,  ///< binary_little_endian 1.0
  ascii,   ///< ascii 1.0
};

namespace detail::ply {

using io::errno_text;
using io::fail;
using io::File;
using io::quoted;

// ---- writing -----------------------------------------------------------------

/// Appends little-endian bytes whatever the host byte order.
inline void append_le(std::string& out, std::uint32_t bits) {
  for (int i = 0; i < 4; ++i) out.push_back(char((bits >> (8 * i)) & 0xffu));
}
inline void append_le(std::string& out, float value) { append_le(out, std::bit_cast<std::uint32_t>(value)); }

inline void append_ascii(std::string& out, float value) {
  char buffer[32];
  // Shortest text that reads back as the same float.
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out.append(buffer, result.ptr);
}
inline void append_ascii(std::string& out, int value) { out += std::to_string(value); }

/// Writes out and empties the chunk of file content built so far; the
/// writer flushes every few MB so that large meshes are never held twice.
/// Returns 0 or the errno of the failure.
inline int flush_to(std::FILE* file, std::string& chunk) {
  errno = 0;
  const bool ok = std::fwrite(chunk.data(), 1, chunk.size(), file) == chunk.size();
  chunk.clear();
  return ok ? 0 : (errno != 0 ? errno : EIO);
}

// ---- reading -----------------------------------------------------------------

enum class Type { int8, uint8, int16, uint16, int32, uint32, float32, float64 };

inline bool parse_type(const std::string& name, Type& type) {
  struct Named {
    const char* name;
    Type type;
  };
  static constexpr Named names[] = {
      {"char", Type::int8},     {"int8", Type::int8},       {"uchar", Type::uint8},    {"uint8", Type::uint8},
      {"short", Type::int16},   {"int16", Type::int16},     {"ushort", Type::uint16},  {"uint16", Type::uint16},
      {"int", Type::int32},     {"int32", Type::int32},     {"uint", Type::uint32},    {"uint32", Type::uint32},
      {"float", Type::float32}, {"float32", Type::float32}, {"double", Type::float64}, {"float64", Type::float64}};
  for (const auto& n : names)
    if (name == n.name) {
      type = n.type;
      return true;
    }
  return false;
}

inline std::size_t type_size(Type t) {
  switch (t) {
    case Type::int8:
    case Type::uint8:
      return 1;
    case Type::int16:
    case Type::uint16:
      return 2;
    case Type::int32:
    case Type::uint32:
    case Type::float32:
      return 4;
    case Type::float64:
      return 8;
  }
  return 0;
}

inline bool is_integer(Type t) { return t != Type::float32 && t != Type::float64; }

struct Property {
  std::string name;
  Type type = Type::float32;
  bool is_list = false;
  Type count_type = Type::uint8;  // lists only
};

struct Element {
  std::string name;
  std::size_t count = 0;
  std::vector<Property> properties;
};

enum class Encoding { ascii, little_endian, big_endian };

struct Header {
  Encoding encoding = Encoding::ascii;
  std::vector<Element> elements;
  std::size_t body_offset = 0;
};

inline std::vector<std::string> split_words(std::string_view line) {
  std::vector<std::string> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    if (i > start) words.emplace_back(line.substr(start, i - start));
  }
  return words;
}

inline Header parse_header(const std::string& data, const std::string& path) {
  constexpr const char* where = "read_ply";
  Header header;
  std::size_t pos = 0;
  bool seen_format = false;
  for (int line_number = 1;; ++line_number) {
    const std::size_t end = data.find('\n', pos);
    if (end == std::string::npos) {
      if (line_number == 1 && data.rfind("ply", 0) != 0)
        fail(where, path, "not a PLY file (it does not start with \"ply\")");
      fail(where, path, "truncated header (no end_header line)");
    }
    std::string_view line(data.data() + pos, end - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = end + 1;
    if (line_number == 1) {
      if (line != "ply") fail(where, path, "not a PLY file (it does not start with \"ply\")");
      continue;
    }
    const std::vector<std::string> w = split_words(line);
    const std::string at = " in header line " + std::to_string(line_number);
    if (w.empty() || w[0] == "comment" || w[0] == "obj_info") continue;
    if (w[0] == "end_header") break;
    if (w[0] == "format") {
      if (w.size() != 3) fail(where, path, "malformed format line" + at);
      if (w[1] == "ascii")
        header.encoding = Encoding::ascii;
      else if (w[1] == "binary_little_endian")
        header.encoding = Encoding::little_endian;
      else if (w[1] == "binary_big_endian")
        header.encoding = Encoding::big_endian;
      else
        fail(where, path, "unsupported format '" + w[1] + "'" + at);
      if (w[2] != "1.0") fail(where, path, "unsupported format version '" + w[2] + "'" + at);
      seen_format = true;
    } else if (w[0] == "element") {
      Element element;
      if (w.size() != 3) fail(where, path, "malformed element line" + at);
      element.name = w[1];
      const auto r = std::from_chars(w[2].data(), w[2].data() + w[2].size(), element.count);
      if (r.ec != std::errc() || r.ptr != w[2].data() + w[2].size())
        fail(where, path, "bad element count '" + w[2] + "'" + at);
      header.elements.push_back(element);
    } else if (w[0] == "property") {
      if (header.elements.empty()) fail(where, path, "property before any element" + at);
      Property p;
      const bool list = w.size() >= 2 && w[1] == "list";
      if (w.size() != (list ? 5u : 3u)) fail(where, path, "malformed property line" + at);
      p.is_list = list;
      const std::string& type = list ? w[3] : w[1];
      if (!parse_type(type, p.type)) fail(where, path, "unsupported property type '" + type + "'" + at);
      if (list) {
        if (!parse_type(w[2], p.count_type) || !is_integer(p.count_type))
          fail(where, path, "unsupported list count type '" + w[2] + "'" + at);
      }
      p.name = w.back();
      header.elements.back().properties.push_back(p);
    } else {
      fail(where, path, "unexpected header line '" + std::string(line) + "'" + at);
    }
  }
  if (!seen_format) fail(where, path, "the header has no format line");
  header.body_offset = pos;
  return header;
}

/// Reads scalars from the body, ascii tokens or binary values in either byte
/// order, and reports running out of data as truncation.
class BodyReader {
 public:
  BodyReader(const std::string& data, std::size_t offset, Encoding encoding, const std::string& path)
      : data_(data), pos_(offset), encoding_(encoding), path_(path) {}

  /// Names what is being read, for error messages.
  void set_context(const std::string& element, std::size_t item, std::size_t count) {
    element_ = &element, item_ = item, count_ = count;
  }

  double read(Type type) { return encoding_ == Encoding::ascii ? read_ascii(type) : read_binary(type); }

  [[noreturn]] void truncated() const {
    fail("read_ply", path_,
         "truncated data in element '" + *element_ + "' (item " + std::to_string(item_) + " of " +
             std::to_string(count_) + ")");
  }

 private:
  double read_binary(Type type) {
    const std::size_t n = type_size(type);
    if (data_.size() - pos_ < n) truncated();
    std::uint64_t bits = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t byte = encoding_ == Encoding::little_endian ? i : n - 1 - i;
      bits |= std::uint64_t(static_cast<unsigned char>(data_[pos_ + i])) << (8 * byte);
    }
    pos_ += n;
    switch (type) {
      case Type::int8:
        return double(std::int8_t(std::uint8_t(bits)));
      case Type::uint8:
        return double(std::uint8_t(bits));
      case Type::int16:
        return double(std::int16_t(std::uint16_t(bits)));
      case Type::uint16:
        return double(std::uint16_t(bits));
      case Type::int32:
        return double(std::int32_t(std::uint32_t(bits)));
      case Type::uint32:
        return double(std::uint32_t(bits));
      case Type::float32:
        return double(std::bit_cast<float>(std::uint32_t(bits)));
      case Type::float64:
        return std::bit_cast<double>(bits);
    }
    return 0;
  }

  double read_ascii(Type type) {
    while (pos_ < data_.size() && is_space(data_[pos_])) ++pos_;
    if (pos_ == data_.size()) truncated();
    std::size_t end = pos_;
    while (end < data_.size() && !is_space(data_[end])) ++end;
    const char* first = data_.data() + pos_;
    const char* last = data_.data() + end;
    double value = 0;
    std::from_chars_result r{};
    if (type == Type::float32) {
      // Parsed as float directly: going through double could round twice.
      float f = 0;
      r = std::from_chars(first, last, f);
      value = f;
    } else {
      r = std::from_chars(first, last, value);
    }
    if (r.ec != std::errc() || r.ptr != last)
      fail("read_ply", path_,
           "bad number '" + std::string(first, last) + "' in element '" + *element_ + "' (item " +
               std::to_string(item_) + ")");
    pos_ = end;
    return value;
  }

  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

  const std::string& data_;
  std::size_t pos_;
  Encoding encoding_;
  const std::string& path_;
  const std::string* element_ = nullptr;
  std::size_t item_ = 0, count_ = 0;
};

}  // namespace detail::ply

/// Writes `mesh` to `path` (see the top of this header for the layout).
/// Throws std::invalid_argument if the mesh is inconsistent (normal count,
/// vertex indices), std::runtime_error if the file cannot be written; in both
/// cases any earlier file at `path` is left as it was.
template <class S>
void write_ply(const std::string& path, const TriangleMesh<S>& mesh, PlyFormat format = PlyFormat::binary) {
  namespace ply = detail::ply;
  const std::size_t vertex_count = mesh.vertices.size();
  const bool with_normals = !mesh.normals.empty();
  if (with_normals && mesh.normals.size() != vertex_count)
    throw std::invalid_argument("write_ply: " + ply::quoted(path) + ": the mesh has " +
                                std::to_string(mesh.normals.size()) + " normals for " + std::to_string(vertex_count) +
                                " vertices");
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i)
    for (const int v : mesh.triangles[i])
      if (v < 0 || std::size_t(v) >= vertex_count)
        throw std::invalid_argument("write_ply: " + ply::quoted(path) + ": triangle " + std::to_string(i) +
                                    " refers to vertex " + std::to_string(v) + ", out of range for " +
                                    std::to_string(vertex_count) + " vertices");

  detail::io::AtomicFile file("write_ply", path);

  const bool binary = format == PlyFormat::binary;
  std::string chunk =
      std::string("ply\nformat ") + (binary ? "binary_little_endian" : "ascii") + " 1.0\ncomment written by emfusion\n";
  chunk += "element vertex " + std::to_string(vertex_count) + "\n";
  chunk += "property float x\nproperty float y\nproperty float z\n";
  if (with_normals) chunk += "property float nx\nproperty float ny\nproperty float nz\n";
  chunk += "element face " + std::to_string(mesh.triangles.size()) + "\n";
  chunk += "property list uchar int vertex_indices\nend_header\n";

  constexpr std::size_t chunk_bytes = std::size_t(1) << 22;
  int error = 0;
  const auto put_float = [&](S value) {
    const float f = static_cast<float>(value);
    if (binary) {
      ply::append_le(chunk, f);
    } else {
      ply::append_ascii(chunk, f);
      chunk.push_back(' ');
    }
  };
  for (std::size_t i = 0; i < vertex_count && error == 0; ++i) {
    for (int a = 0; a < 3; ++a) put_float(mesh.vertices[i][a]);
    if (with_normals)
      for (int a = 0; a < 3; ++a) put_float(mesh.normals[i][a]);
    if (!binary) chunk.back() = '\n';
    if (chunk.size() >= chunk_bytes) error = ply::flush_to(file.get(), chunk);
  }
  for (std::size_t i = 0; i < mesh.triangles.size() && error == 0; ++i) {
    const auto& t = mesh.triangles[i];
    if (binary) {
      chunk.push_back(char(3));
      for (const int v : t) ply::append_le(chunk, std::uint32_t(v));
    } else {
      chunk += "3";
      for (const int v : t) {
        chunk.push_back(' ');
        ply::append_ascii(chunk, v);
      }
      chunk.push_back('\n');
    }
    if (chunk.size() >= chunk_bytes) error = ply::flush_to(file.get(), chunk);
  }
  if (error == 0) error = ply::flush_to(file.get(), chunk);
  file.commit(error == 0 ? "" : ply::errno_text(error));
}

/// Reads a triangle mesh from a PLY file: the "vertex" element's x, y, z
/// (and nx, ny, nz when all three are present) and the "face" element's
/// vertex_indices (or vertex_index) list, polygons fanned into triangles.
template <class S = float>
TriangleMesh<S> read_ply(const std::string& path) {
  namespace ply = detail::ply;
  constexpr const char* where = "read_ply";
  const std::string data = detail::io::read_file(path, "read_ply");
  const ply::Header header = ply::parse_header(data, path);

  const ply::Element* vertex_element = nullptr;
  for (const auto& e : header.elements)
    if (e.name == "vertex") vertex_element = &e;
  if (!vertex_element) ply::fail(where, path, "no vertex element");
  // Where each vertex attribute sits among the vertex properties.
  int slot[6] = {-1, -1, -1, -1, -1, -1};
  const char* attribute_names[6] = {"x", "y", "z", "nx", "ny", "nz"};
  for (std::size_t p = 0; p < vertex_element->properties.size(); ++p)
    for (int a = 0; a < 6; ++a)
      if (vertex_element->properties[p].name == attribute_names[a] && !vertex_element->properties[p].is_list)
        slot[a] = int(p);
  if (slot[0] < 0 || slot[1] < 0 || slot[2] < 0) ply::fail(where, path, "the vertex element lacks x, y or z");
  const bool with_normals = slot[3] >= 0 && slot[4] >= 0 && slot[5] >= 0;
  if (vertex_element->count > std::size_t(INT32_MAX))
    ply::fail(where, path, "too many vertices (" + std::to_string(vertex_element->count) + ")");

  TriangleMesh<S> mesh;
  ply::BodyReader reader(data, header.body_offset, header.encoding, path);
  for (const auto& element : header.elements) {
    const bool is_vertex = &element == vertex_element;
    const bool is_face = element.name == "face";
    if (is_vertex) {
      // Reserve only what the file could hold, so a corrupt count cannot
      // make us allocate without bound.
      const std::size_t plausible = std::min(element.count, data.size());
      mesh.vertices.reserve(plausible);
      if (with_normals) mesh.normals.reserve(plausible);
    }
    std::vector<double> values(element.properties.size());
    std::vector<std::int64_t> polygon;
    for (std::size_t item = 0; item < element.count; ++item) {
      reader.set_context(element.name, item, element.count);
      bool have_polygon = false;
      for (std::size_t p = 0; p < element.properties.size(); ++p) {
        const auto& property = element.properties[p];
        if (!property.is_list) {
          values[p] = reader.read(property.type);
          continue;
        }
        const double n = reader.read(property.count_type);
        if (!(n >= 0) || n != std::floor(n))
          ply::fail(where, path,
                    "bad list length in element '" + element.name + "' (item " + std::to_string(item) + ")");
        const bool is_indices =
            is_face && !have_polygon && (property.name == "vertex_indices" || property.name == "vertex_index");
        if (is_indices) polygon.clear();
        for (std::size_t k = 0; k < std::size_t(n); ++k) {
          const double v = reader.read(property.type);
          if (is_indices) {
            if (v != std::floor(v))
              ply::fail(where, path, "face " + std::to_string(item) + " has a non-integer vertex index");
            polygon.push_back(std::int64_t(v));
          }
        }
        have_polygon = have_polygon || is_indices;
      }
      if (is_vertex) {
        mesh.vertices.push_back(vec3(S(values[slot[0]]), S(values[slot[1]]), S(values[slot[2]])));
        if (with_normals) mesh.normals.push_back(vec3(S(values[slot[3]]), S(values[slot[4]]), S(values[slot[5]])));
      }
      if (have_polygon) {
        if (polygon.size() < 3)
          ply::fail(where, path,
                    "face " + std::to_string(item) + " has " + std::to_string(polygon.size()) +
                        " vertices; at least 3 are needed");
        for (const std::int64_t v : polygon)
          if (v < 0 || std::uint64_t(v) >= vertex_element->count)
            ply::fail(where, path,
                      "face " + std::to_string(item) + " refers to vertex " + std::to_string(v) +
                          ", out of range for " + std::to_string(vertex_element->count) + " vertices");
        for (std::size_t k = 1; k + 1 < polygon.size(); ++k)
          mesh.triangles.push_back({int(polygon[0]), int(polygon[k]), int(polygon[k + 1])});
      }
    }
  }
  return mesh;
}

}  // namespace emfusion

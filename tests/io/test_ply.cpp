// PLY meshes: write/read round trips in both formats, files from other tools
// (polygons, extra properties, big-endian), and clear errors for bad paths
// and bad files, with no damage to an existing file when a write fails.
#include <unistd.h>
#include <array>
#include <bit>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "emfusion/io/ply.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
namespace fs = std::filesystem;
using emfusion::test::ScratchDir;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::read_bytes;
using emfusion::test::write_bytes;


namespace {



/// A closed tetrahedron with vertex values that are awkward in
/// text: tiny, negative, not short in decimal.
template <class S>
TriangleMesh<S> tetrahedron(bool with_normals) {
  TriangleMesh<S> mesh;
  mesh.vertices = {vec3(S(0.1), S(-2.5e-7), S(3.14159265)), vec3(S(1.0 / 3.0), S(0), S(-1e6)),
                   vec3(S(-0.7), S(1234.5678), S(2)), vec3(S(1e-30), S(-0.0), S(0.6))};
  if (with_normals)
    for (const auto& v : mesh.vertices) mesh.normals.push_back(normalized(v));
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

/// Positions and normals are stored as float: compare against the mesh
/// rounded to float, exactly.
template <class S>
void check_equal_after_float_storage(const TriangleMesh<S>& written, const TriangleMesh<S>& read) {
  REQUIRE(read.vertices.size() == written.vertices.size());
  REQUIRE(read.normals.size() == written.normals.size());
  CHECK(read.triangles == written.triangles);
  for (std::size_t i = 0; i < written.vertices.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      CHECK(read.vertices[i][a] == S(float(written.vertices[i][a])));
      if (!written.normals.empty()) CHECK(read.normals[i][a] == S(float(written.normals[i][a])));
    }
}

const char* format_name(PlyFormat f) { return f == PlyFormat::binary ? "binary" : "ascii"; }

}  // namespace

TEMPLATE_TEST_CASE("ply: write then read gives the same mesh", "[io]", float, double) {
  using S = TestType;
  ScratchDir dir;
  for (const PlyFormat format : {PlyFormat::binary, PlyFormat::ascii})
    for (const bool with_normals : {true, false}) {
      INFO(format_name(format) << (with_normals ? " with" : " without") << " normals");
      const std::string path = dir.file("mesh.ply");
      const TriangleMesh<S> mesh = tetrahedron<S>(with_normals);
      write_ply(path, mesh, format);
      CHECK(!fs::exists(path + ".tmp"));
      const TriangleMesh<S> back = read_ply<S>(path);
      check_equal_after_float_storage(mesh, back);
      CHECK(back.has_normals() == with_normals);
      CHECK(count_edges(back).closed());
      CHECK(enclosed_volume(back) == emfusion::test::Approx(enclosed_volume(mesh)).epsilon(1e-5));
    }
}

TEST_CASE("ply: files have the documented layout", "[io]") {
  ScratchDir dir;
  const auto mesh = tetrahedron<float>(true);
  const std::string path = dir.file("layout.ply");
  write_ply(path, mesh);
  const std::string bytes = read_bytes(path);
  const std::string header_end = "end_header\n";
  const std::size_t body = bytes.find(header_end) + header_end.size();
  REQUIRE(body > header_end.size());
  CHECK(bytes.rfind("ply\nformat binary_little_endian 1.0\n", 0) == 0);
  CHECK(contains(bytes.substr(0, body), "element vertex 4\n"));
  CHECK(contains(bytes.substr(0, body), "property float nz\n"));
  CHECK(contains(bytes.substr(0, body), "element face 4\nproperty list uchar int vertex_indices\n"));
  // 4 vertices x 6 floats, 4 faces x (1 + 3 x 4) bytes.
  CHECK(bytes.size() - body == 4 * 6 * 4 + 4 * 13);
  // The first x, little-endian.
  std::uint32_t bits = 0;
  for (int i = 0; i < 4; ++i) bits |= std::uint32_t(static_cast<unsigned char>(bytes[body + i])) << (8 * i);
  CHECK(std::bit_cast<float>(bits) == 0.1f);

  write_ply(path, mesh, PlyFormat::ascii);
  const std::string text = read_bytes(path);
  CHECK(text.rfind("ply\nformat ascii 1.0\n", 0) == 0);
  CHECK(contains(text, "\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"));
}

TEST_CASE("ply: files from other tools: polygons, extra properties, big-endian, CRLF", "[io]") {
  ScratchDir dir;
  const std::string path = dir.file("other.ply");
  SECTION("ascii quad with colours and an extra element") {
    write_bytes(path,
                "ply\r\nformat ascii 1.0\r\ncomment from elsewhere\r\n"
                "element vertex 4\r\nproperty double x\r\nproperty double y\r\nproperty double z\r\n"
                "property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n"
                "element face 1\r\nproperty uchar flags\r\nproperty list uchar uint vertex_index\r\n"
                "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\n"
                "end_header\r\n"
                "0 0 0 255 0 0\r\n1 0 0 0 255 0\r\n1 1 0 0 0 255\r\n0 1 0 9 9 9\r\n"
                "7 4 0 1 2 3\r\n"
                "0 1\r\n");
    const auto mesh = read_ply<double>(path);
    REQUIRE(mesh.vertices.size() == 4);
    CHECK(!mesh.has_normals());
    CHECK(mesh.vertices[2][0] == 1.0);
    CHECK(mesh.vertices[2][1] == 1.0);
    REQUIRE(mesh.triangles.size() == 2);
    CHECK(mesh.triangles[0] == std::array<int, 3>{0, 1, 2});
    CHECK(mesh.triangles[1] == std::array<int, 3>{0, 2, 3});
    CHECK(surface_area(mesh) == emfusion::test::Approx(1.0));
  }
  SECTION("big-endian binary") {
    std::string bytes =
        "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    const auto put_be = [&](std::uint32_t bits) {
      for (int i = 3; i >= 0; --i) bytes.push_back(char((bits >> (8 * i)) & 0xffu));
    };
    const float xyz[9] = {0, 0, 0, 2, 0, 0, 0, 3, 0};
    for (const float v : xyz) put_be(std::bit_cast<std::uint32_t>(v));
    bytes.push_back(char(3));
    for (const std::uint32_t i : {0u, 1u, 2u}) put_be(i);
    write_bytes(path, bytes);
    const auto mesh = read_ply<float>(path);
    REQUIRE(mesh.vertices.size() == 3);
    CHECK(mesh.vertices[1][0] == 2.0f);
    CHECK(mesh.vertices[2][1] == 3.0f);
    REQUIRE(mesh.triangles.size() == 1);
    CHECK(surface_area(mesh) == emfusion::test::Approx(3.0));
  }
}

TEST_CASE("ply: writing to an unwritable path names the path", "[io]") {
  const std::string path = "/nonexistent-dir/x.ply";
  const std::string message = error_of([&] { write_ply(path, tetrahedron<float>(false)); });
  INFO(message);
  CHECK(contains(message, path));
  CHECK(contains(message, "cannot open"));
  CHECK(contains(message, "No such file or directory"));
  CHECK_THROWS_AS(write_ply(path, tetrahedron<float>(false)), std::runtime_error);
}

TEST_CASE("ply: a failed write leaves the earlier file untouched", "[io]") {
  ScratchDir dir;
  const std::string path = dir.file("keep.ply");
  write_ply(path, tetrahedron<double>(true));
  const std::string before = read_bytes(path);

  SECTION("the temporary file cannot be created") {
    fs::create_directory(path + ".tmp");  // opening a directory for writing fails
    const std::string message = error_of([&] { write_ply(path, tetrahedron<double>(false), PlyFormat::ascii); });
    INFO(message);
    CHECK(contains(message, path));
    CHECK(contains(message, "cannot open"));
  }
  SECTION("the mesh is inconsistent") {
    auto bad = tetrahedron<double>(true);
    bad.triangles.push_back({0, 1, 4});
    const std::string message = error_of([&] { write_ply(path, bad); });
    INFO(message);
    CHECK(contains(message, path));
    CHECK(contains(message, "vertex 4"));
    CHECK_THROWS_AS(write_ply(path, bad), std::invalid_argument);
    CHECK(!fs::exists(path + ".tmp"));

    bad = tetrahedron<double>(true);
    bad.normals.pop_back();
    CHECK(contains(error_of([&] { write_ply(path, bad); }), "3 normals for 4 vertices"));
  }
  CHECK(read_bytes(path) == before);
}

TEST_CASE("ply: bad files give errors naming the file and the problem", "[io]") {
  ScratchDir dir;
  const std::string path = dir.file("bad.ply");
  const auto read_error = [&] { return error_of([&] { read_ply<float>(path); }); };
  const std::string good_header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";

  SECTION("missing file") {
    const std::string message = read_error();
    INFO(message);
    CHECK(contains(message, path));
    CHECK(contains(message, "cannot open"));
    CHECK_THROWS_AS(read_ply<float>(path), std::runtime_error);
  }
  SECTION("not a PLY file") {
    write_bytes(path, "solid cube\nfacet normal 0 0 1\n");
    const std::string message = read_error();
    INFO(message);
    CHECK(contains(message, path));
    CHECK(contains(message, "not a PLY file"));
  }
  SECTION("empty file") {
    write_bytes(path, "");
    CHECK(contains(read_error(), "not a PLY file"));
  }
  SECTION("header without end_header") {
    write_bytes(path, "ply\nformat ascii 1.0\nelement vertex 3\n");
    CHECK(contains(read_error(), "truncated header"));
  }
  SECTION("unsupported format") {
    write_bytes(path, "ply\nformat binary_middle_endian 1.0\nend_header\n");
    const std::string message = read_error();
    INFO(message);
    CHECK(contains(message, path));
    CHECK(contains(message, "unsupported format 'binary_middle_endian'"));
  }
  SECTION("unsupported property type") {
    write_bytes(path, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n0\n");
    CHECK(contains(read_error(), "unsupported property type 'float128'"));
  }
  SECTION("no coordinates") {
    write_bytes(path, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float u\nend_header\n0\n");
    CHECK(contains(read_error(), "lacks x, y or z"));
  }
  SECTION("truncated binary data") {
    const std::string good = dir.file("good.ply");
    write_ply(good, tetrahedron<float>(true));
    const std::string bytes = read_bytes(good);
    for (const std::size_t cut : {std::size_t(5), std::size_t(30), std::size_t(60)}) {
      write_bytes(path, bytes.substr(0, bytes.size() - cut));
      const std::string message = read_error();
      INFO(message);
      CHECK(contains(message, path));
      CHECK(contains(message, "truncated data"));
    }
  }
  SECTION("truncated ascii data") {
    write_bytes(path, good_header + "0 0 0\n1 0 0\n0 1\n");
    const std::string message = read_error();
    INFO(message);
    CHECK(contains(message, "truncated data in element 'vertex' (item 2 of 3)"));
  }
  SECTION("garbage in ascii data") {
    write_bytes(path, good_header + "0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n");
    CHECK(contains(read_error(), "bad number 'zero'"));
  }
  SECTION("face index out of range") {
    write_bytes(path, good_header + "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n");
    const std::string message = read_error();
    INFO(message);
    CHECK(contains(message, path));
    CHECK(contains(message, "face 0 refers to vertex 7, out of range for 3 vertices"));
  }
  SECTION("negative face index") {
    write_bytes(path, good_header + "0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n");
    CHECK(contains(read_error(), "refers to vertex -1"));
  }
  SECTION("degenerate face") {
    write_bytes(path, good_header + "0 0 0\n1 0 0\n0 1 0\n2 0 1\n");
    CHECK(contains(read_error(), "face 0 has 2 vertices"));
  }
}

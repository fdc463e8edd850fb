// Instance-mask directories (io/masks.hpp): write/read round trips, 8- and
// 16-bit label images, detect() matching by nearest timestamp within 0.02 s,
// every kind of bad masks.txt line and bad label image reported with file,
// line and problem, the writer's argument checks, and the real
// room_dyn_300/masks when shared/data is there.
#include <png.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "emfusion/detect/detection.hpp"
#include "emfusion/io/masks.hpp"
#include "emfusion/io/png.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
namespace fs = std::filesystem;
using emfusion::test::Approx;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::ScratchDir;

static_assert(Segmenter<MaskDirectory>);

namespace {

/// A width x height label image: pixel k holds pattern[k % pattern.size()].
Image<std::uint16_t, Host> labels_of(const std::vector<std::uint16_t>& pattern, int width = 6, int height = 4) {
  std::vector<std::uint16_t> pixels(std::size_t(width * height));
  for (std::size_t k = 0; k < pixels.size(); ++k) pixels[k] = pattern[k % pattern.size()];
  return Image<std::uint16_t, Host>::from_host(width, height, pixels);
}

Detections frame_of(double timestamp, Image<std::uint16_t, Host> labels, std::vector<Instance> instances) {
  Detections d;
  d.timestamp = timestamp;
  d.labels = std::move(labels);
  d.instances = std::move(instances);
  return d;
}

void check_same(const Detections& got, const Detections& expected) {
  CHECK(got.timestamp == expected.timestamp);
  REQUIRE(got.instances.size() == expected.instances.size());
  for (std::size_t k = 0; k < got.instances.size(); ++k) {
    CAPTURE(k);
    CHECK(got.instances[k].label == expected.instances[k].label);
    CHECK(got.instances[k].class_name == expected.instances[k].class_name);
    CHECK(got.instances[k].score == expected.instances[k].score);
  }
  REQUIRE(got.labels.same_size(expected.labels.width(), expected.labels.height()));
  CHECK(got.labels.to_host() == expected.labels.to_host());
}

/// A masks directory in `dir`/masks with the given masks.txt and 6x4 label
/// images a.png (values 0, 1, 2, 16-bit) and b.png (0 and 1).
std::string write_masks_dir(const ScratchDir& dir, const std::string& masks_txt) {
  const std::string masks = dir.file("masks");
  fs::create_directories(masks);
  write_png(masks + "/a.png", labels_of({0, 1, 2}));
  write_png(masks + "/b.png", labels_of({0, 1}));
  dir.write("masks/masks.txt", masks_txt);
  return masks;
}

/// The message of MaskDirectory::open on a directory with this masks.txt.
std::string open_error(const std::string& masks_txt) {
  const ScratchDir dir;
  const std::string masks = write_masks_dir(dir, masks_txt);
  return error_of([&] { MaskDirectory::open(masks); });
}

/// Writes an 8-bit RGB PNG through libpng's simplified API.
void write_rgb_png(const std::string& path, int width, int height) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = png_uint_32(width);
  image.height = png_uint_32(height);
  image.format = PNG_FORMAT_RGB;
  const std::vector<png_byte> pixels(std::size_t(width * height * 3), 7);
  REQUIRE(png_image_write_to_file(&image, path.c_str(), 0, pixels.data(), 0, nullptr) != 0);
}

}  // namespace

// ---- round trips ------------------------------------------------------------------------

TEST_CASE("write_mask_directory and MaskDirectory round-trip frames exactly", "[io][masks]") {
  const ScratchDir dir;
  const std::vector<Detections> frames = {
      frame_of(1305031102.175304, labels_of({0, 1, 2, 300, 65535}),
               {{1, "cup", 0.924}, {2, "teddy_bear", 1.0}, {300, "book", 0.0}, {65535, "car", 0.1 + 0.2}}),
      frame_of(1305031102.2, labels_of({0}), {}),                                        // ran, found nothing
      frame_of(1305031103.5, labels_of({0, 4}), {{4, "cup", 0.5}, {9, "chair", 0.75}}),  // 9: empty mask
  };
  const std::string masks = dir.file("out/nested/masks");  // parents are created
  write_mask_directory(masks, frames);
  CHECK(fs::is_regular_file(masks + "/masks.txt"));
  CHECK(fs::is_regular_file(masks + "/000000.png"));
  CHECK(fs::is_regular_file(masks + "/000002.png"));
  CHECK_FALSE(fs::exists(masks + "/masks.txt.tmp"));
  // The label images are 16-bit.
  CHECK(error_of([&] { read_png_u8(masks + "/000000.png"); }) != "");

  const MaskDirectory m = MaskDirectory::open(masks, 6, 4);
  REQUIRE(m.size() == 3);
  CHECK(m.dir() == masks);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    CAPTURE(i);
    CHECK(m.timestamp(i) == frames[i].timestamp);
    CHECK(m.instances(i).size() == frames[i].instances.size());
    check_same(m.read(i), frames[i]);
  }
  CHECK(m.read(1).instances.empty());
  CHECK(m.read(2).find(9) != nullptr);
  CHECK(m.read(2).find(5) == nullptr);
  CHECK_THROWS_AS(m.read(3), std::out_of_range);
  CHECK_THROWS_AS(m.timestamp(3), std::out_of_range);

  // The written list is the documented format.
  const std::string text = test::read_bytes(masks + "/masks.txt");
  CHECK(contains(text, "1305031102.175304 000000.png 1:cup:0.924 2:teddy_bear:1 300:book:0 65535:car:"));
  CHECK(contains(text, "\n1305031102.2 000001.png\n"));

  // Writing again replaces the directory's files.
  write_mask_directory(masks, {frames[1]});
  CHECK(MaskDirectory::open(masks).size() == 1);
}

TEST_CASE("write_mask_directory takes label image names, with subfolders", "[io][masks]") {
  const ScratchDir dir;
  const std::vector<Detections> frames = {frame_of(0.0, labels_of({0, 1}), {{1, "cup", 0.9}}),
                                          frame_of(1.0, labels_of({2, 0}), {{2, "book", 0.8}})};
  write_mask_directory(dir.path(), frames, {"000000.png", "labels/000030.png"});
  CHECK(fs::is_regular_file(dir.file("labels/000030.png")));
  const MaskDirectory m = MaskDirectory::open(dir.path());
  REQUIRE(m.size() == 2);
  CHECK(m.label_path(1) == (fs::path(dir.path()) / "labels/000030.png").string());
  check_same(m.read(0), frames[0]);
  check_same(m.read(1), frames[1]);

  // No frames: an empty masks.txt, read back as no entries.
  const std::string empty = dir.file("empty");
  write_mask_directory(empty, {});
  const MaskDirectory none = MaskDirectory::open(empty);
  CHECK(none.size() == 0);
  CHECK_FALSE(none.detect(0, 0.0).has_value());
}

TEST_CASE("MaskDirectory reads 8-bit and 16-bit label images, values unchanged", "[io][masks]") {
  const ScratchDir dir;
  std::vector<std::uint8_t> narrow(6 * 4);
  for (std::size_t k = 0; k < narrow.size(); ++k) narrow[k] = k % 3 == 0 ? 0 : (k % 3 == 1 ? 7 : 255);
  write_png(dir.file("eight.png"), Image<std::uint8_t, Host>::from_host(6, 4, narrow));
  write_png(dir.file("sixteen.png"), labels_of({0, 7, 256, 65535}));
  dir.write("masks.txt",
            "# timestamp label_png [id:class:score ...]\n"
            "0.5 eight.png 7:cup:0.5 255:book:1   # comment\n"
            "\n"
            "0.6\tsixteen.png\t7:cup:0.25,256:car:+0.125  65535:book:1e-3\r\n");
  const MaskDirectory m = MaskDirectory::open(dir.path(), 6, 4);
  REQUIRE(m.size() == 2);

  const Detections eight = m.read(0);
  REQUIRE(eight.labels.same_size(6, 4));
  const std::vector<std::uint16_t> eight_pixels = eight.labels.to_host();
  for (std::size_t k = 0; k < narrow.size(); ++k) CHECK(eight_pixels[k] == narrow[k]);
  REQUIRE(eight.instances.size() == 2);
  CHECK(eight.instances[1].label == 255);
  CHECK(eight.instances[1].class_name == "book");
  CHECK(eight.instances[1].score == 1.0);

  const Detections sixteen = m.read(1);
  CHECK(sixteen.labels.to_host() == labels_of({0, 7, 256, 65535}).to_host());
  REQUIRE(sixteen.instances.size() == 3);
  CHECK(sixteen.instances[1].score == 0.125);
  CHECK(sixteen.instances[2].label == 65535);
  CHECK(sixteen.instances[2].score == 0.001);
  CHECK(sixteen.timestamp == 0.6);
}

// ---- detect ----------------------------------------------------------------------------

TEST_CASE("MaskDirectory::detect matches the nearest timestamp within 0.02 s", "[io][masks]") {
  const ScratchDir dir;
  write_mask_directory(dir.path(),
                       {frame_of(1.0, labels_of({0, 1}), {{1, "cup", 0.9}}), frame_of(1.03, labels_of({0}), {}),
                        frame_of(2.0, labels_of({0, 3}), {{3, "car", 0.7}})});
  MaskDirectory m = MaskDirectory::open(dir.path(), 6, 4);

  const auto at = [&](double t) -> int {
    const std::optional<Detections> d = m.detect(0, t);
    if (!d) return -1;
    for (std::size_t i = 0; i < m.size(); ++i)
      if (m.timestamp(i) == d->timestamp) return int(i);
    FAIL("detect returned an unknown timestamp " << d->timestamp);
    return -2;
  };
  CHECK(at(1.0) == 0);
  CHECK(at(0.99) == 0);
  CHECK(at(0.98) == 0);    // exactly 0.02 s before: matches
  CHECK(at(0.979) == -1);  // just outside
  CHECK(at(1.014) == 0);   // nearer to 1.0 than to 1.03
  CHECK(at(1.016) == 1);   // nearer to 1.03
  CHECK(at(1.05) == 1);
  CHECK(at(1.051) == -1);
  CHECK(at(1.5) == -1);  // not listed: no detector result
  CHECK(at(2.02) == 2);
  CHECK(at(2.021) == -1);
  CHECK(at(-100.0) == -1);
  CHECK(at(std::nan("")) == -1);
  CHECK(m.nearest(1.016) == std::optional<std::size_t>(1));

  // The frame index plays no part.
  CHECK(m.detect(12345, 2.0).has_value());

  // Listed without instances: present, empty, with its label image.
  const std::optional<Detections> nothing = m.detect(1, 1.03);
  REQUIRE(nothing.has_value());
  CHECK(nothing->instances.empty());
  CHECK(nothing->labels.same_size(6, 4));

  const std::optional<Detections> car = m.detect(2, 2.001);
  REQUIRE(car.has_value());
  REQUIRE(car->find(3) != nullptr);
  CHECK(car->find(3)->class_name == "car");
}

// ---- bad masks.txt ---------------------------------------------------------------------

TEST_CASE("MaskDirectory::open reports missing directories and files", "[io][masks]") {
  const ScratchDir dir;
  const std::string missing = dir.file("nowhere");
  std::string e = error_of([&] { MaskDirectory::open(missing); });
  CAPTURE(e);
  CHECK(contains(e, "MaskDirectory::open: '" + missing + "': directory not found"));

  const std::string file = dir.write("a_file", "x");
  e = error_of([&] { MaskDirectory::open(file); });
  CHECK(contains(e, "'" + file + "': not a directory"));

  e = error_of([&] { MaskDirectory::open(dir.path()); });
  CHECK(contains(e, "'" + dir.file("masks.txt") + "': not found"));

  e = open_error("0.0 a.png 1:cup:0.9\n# two\n1.0 gone.png\n");
  CHECK(contains(e, "masks.txt' line 3: label image '"));
  CHECK(contains(e, "gone.png' not found"));

  CHECK_THROWS_AS(MaskDirectory::open(dir.path(), -1, 4), std::invalid_argument);
  CHECK_THROWS_AS(MaskDirectory::open(dir.path(), 640, 0), std::invalid_argument);
}

TEST_CASE("MaskDirectory::parse checks masks.txt text without the file system", "[io][masks]") {
  const MaskDirectory m = MaskDirectory::parse("0.5 a.png 1:cup:0.9 2:book:0.5\n0.6 sub/b.png\n", "nowhere", 64, 48);
  REQUIRE(m.size() == 2);
  CHECK(m.list_path() == "nowhere/masks.txt");
  CHECK(m.label_path(1) == "nowhere/sub/b.png");
  REQUIRE(m.instances(0).size() == 2);
  CHECK(m.instances(0)[1].class_name == "book");
  CHECK(m.nearest(0.61) == std::optional<std::size_t>(1));
  // The label images are read (and found missing) only by read().
  CHECK_THROWS_WITH(m.read(0), EMF_CONTAINS("MaskDirectory::read: 'nowhere/masks.txt' line 1: cannot read"));
  CHECK_THROWS_WITH(MaskDirectory::parse("0.5 a.png 0:cup:0.9\n", "nowhere"),
                    EMF_CONTAINS("MaskDirectory::open: 'nowhere/masks.txt' line 1: instance '0:cup:0.9'"));
  CHECK_THROWS_AS(MaskDirectory::parse("", "nowhere", 64, 0), std::invalid_argument);
}

TEST_CASE("MaskDirectory::open reports bad masks.txt lines with file, line and problem", "[io][masks]") {
  struct Case {
    const char* line;     // the third line of masks.txt
    const char* problem;  // part of the message
  };
  const std::vector<Case> cases = {
      {"2.0", "expected at least 2 fields (timestamp label_png [id:class:score ...]), got 1"},
      {"two a.png", "timestamp 'two' is not a number"},
      {"inf a.png", "timestamp 'inf' is not a finite number"},
      {"2.0 a.png 1:cup", "instance '1:cup': expected id:class:score"},
      {"2.0 a.png cup", "instance 'cup': expected id:class:score"},
      {"2.0 a.png 1:cup:0.5:x", "instance '1:cup:0.5:x': expected id:class:score, got more than 3"},
      {"2.0 a.png 0:cup:0.5", "instance '0:cup:0.5': id '0' is not an integer in [1, 65535]"},
      {"2.0 a.png 65536:cup:0.5", "id '65536' is not an integer in [1, 65535]"},
      {"2.0 a.png -1:cup:0.5", "id '-1' is not an integer"},
      {"2.0 a.png 1.0:cup:0.5", "id '1.0' is not an integer"},
      {"2.0 a.png x:cup:0.5", "id 'x' is not an integer"},
      {"2.0 a.png :cup:0.5", "id '' is not an integer"},
      {"2.0 a.png 1::0.5", "instance '1::0.5': the class name is empty"},
      {"2.0 a.png 1:cup:high", "instance '1:cup:high': score 'high' is not a number"},
      {"2.0 a.png 1:cup:", "score '' is not a number"},
      {"2.0 a.png 1:cup:nan", "score 'nan' is not a number"},
      {"2.0 a.png 1:cup:1.5", "score '1.5' is not in [0, 1]"},
      {"2.0 a.png 1:cup:-0.1", "score '-0.1' is not in [0, 1]"},
      {"2.0 a.png 1:cup:0.5 2:car:0.5 1:book:0.9", "instance id 1 appears twice ('1:cup:0.5' and '1:book:0.9')"},
      {"1.0 a.png", "timestamp 1.0 is not after the previous one (1 on line 2)"},
      {"0.5 a.png", "timestamp 0.5 is not after the previous one (1 on line 2)"},
      {"2.0 /abs/a.png", "is not relative to the directory"},
      {"2.0 ../a.png", "leaves the directory"},
  };
  for (const Case& c : cases) {
    const std::string e = open_error(std::string("# header\n1.0 b.png 1:cup:0.9\n") + c.line + "\n");
    CAPTURE(c.line, e);
    CHECK(contains(e, "MaskDirectory::open: '"));
    CHECK(contains(e, "masks.txt' line 3: "));
    CHECK(contains(e, c.problem));
  }
}

// ---- bad label images ------------------------------------------------------------------

TEST_CASE("MaskDirectory::read reports bad label images with file, line and problem", "[io][masks]") {
  const ScratchDir dir;
  const std::string masks = write_masks_dir(dir,
                                            "0.0 a.png 1:cup:0.9 2:car:0.8\n"
                                            "1.0 a.png 1:cup:0.9\n"
                                            "2.0 b.png\n"
                                            "3.0 junk.png 1:cup:0.9\n"
                                            "4.0 rgb.png 1:cup:0.9\n"
                                            "5.0 big.png 1:cup:0.9\n");
  dir.write("masks/junk.png", "GIF89a not a png");
  write_rgb_png(masks + "/rgb.png", 6, 4);
  write_png(masks + "/big.png", labels_of({0, 1}, 8, 4));
  const MaskDirectory m = MaskDirectory::open(masks, 6, 4);
  REQUIRE(m.size() == 6);
  CHECK(m.read(0).instances.size() == 2);

  // A value in the image that its line does not list.
  std::string e = error_of([&] { m.read(1); });
  CAPTURE(e);
  CHECK(contains(e, "MaskDirectory::read: '" + masks + "/masks.txt' line 2: label image '"));
  CHECK(contains(e,
                 "a.png' has 8 pixel(s) of value 2 (first at x 2, y 0), which is not an instance id listed on "
                 "this line (listed: 1)"));
  e = error_of([&] { m.read(2); });
  CHECK(contains(e, "masks.txt' line 3: "));
  CHECK(contains(e, "b.png' has 12 pixel(s) of value 1"));
  CHECK(contains(e, "(none listed)"));
  // detect() reports the same.
  CHECK(contains(error_of([&] { m.detect(60, 2.0); }), "of value 1"));

  e = error_of([&] { m.read(3); });
  CHECK(contains(e, "masks.txt' line 4: cannot read the label image: read_png: '"));
  CHECK(contains(e, "junk.png': not a PNG file"));

  e = error_of([&] { m.read(4); });
  CHECK(contains(e, "masks.txt' line 5: cannot read the label image"));
  CHECK(contains(e, "rgb.png': expected a single-channel (grayscale) PNG, got RGB"));

  e = error_of([&] { m.read(5); });
  CHECK(contains(e, "masks.txt' line 6: label image '"));
  CHECK(contains(e, "big.png' is 8x4, expected 6x4"));
  // Without an expected size, any size is taken.
  CHECK(MaskDirectory::open(masks).read(5).labels.same_size(8, 4));

  // A file removed after open().
  fs::remove(masks + "/b.png");
  e = error_of([&] { m.read(2); });
  CHECK(contains(e, "masks.txt' line 3: cannot read the label image"));
  CHECK(contains(e, "b.png': cannot open for reading"));
}

// ---- bad writer arguments --------------------------------------------------------------

TEST_CASE("write_mask_directory rejects what the reader could not read back", "[io][masks]") {
  const ScratchDir dir;
  const std::string out = dir.file("out");
  const auto good = [] { return frame_of(1.0, labels_of({0, 1}), {{1, "cup", 0.9}}); };
  const auto error = [&](std::vector<Detections> frames, std::vector<std::string> names = {}) {
    try {
      write_mask_directory(out, frames, names);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("(no std::invalid_argument)");
  };
  const auto with = [&](auto change) {
    Detections d = good();
    change(d);
    return std::vector<Detections>{d};
  };
  CHECK(contains(error({good(), good()}), "frame 1: timestamp 1 is not after the previous one (1)"));
  CHECK(
      contains(error(with([](Detections& d) { d.timestamp = std::nan(""); })), "frame 0: the timestamp is not finite"));
  CHECK(contains(error(with([](Detections& d) { d.labels = Image<std::uint16_t, Host>(); })),
                 "frame 0: the label image is empty"));
  CHECK(contains(error(with([](Detections& d) { d.instances[0].label = 0; })), "instance id 0 is not in [1, 65535]"));
  CHECK(contains(error(with([](Detections& d) { d.instances[0].label = 70000; })), "instance id 70000 is not in"));
  CHECK(contains(error(with([](Detections& d) {
                   d.instances.push_back({1, "car", 0.5});
                 })),
                 "instance id 1 appears twice"));
  CHECK(contains(error(with([](Detections& d) { d.instances[0].class_name = "teddy bear"; })),
                 "contains white space (write spaces as '_'"));
  CHECK(contains(error(with([](Detections& d) { d.instances[0].class_name = ""; })), "the class name is empty"));
  CHECK(contains(error(with([](Detections& d) { d.instances[0].class_name = "a:b"; })), "contains ':'"));
  CHECK(contains(error(with([](Detections& d) { d.instances[0].score = 1.5; })), "score 1.5 is not in [0, 1]"));
  CHECK(contains(error(with([](Detections& d) { d.instances[0].score = std::nan(""); })), "is not in [0, 1]"));
  CHECK(contains(error(with([](Detections& d) { d.instances.clear(); })),
                 "frame 0: the label image has pixels of value 1, which is not an instance id"));
  CHECK(contains(error({good()}, {"a.png", "b.png"}), "2 label image names for 1 frames"));
  CHECK(contains(error({good()}, {"a b.png"}), "contains white space"));
  CHECK(contains(error({good()}, {"masks.txt"}), "cannot be named masks.txt"));
  CHECK(contains(error({good()}, {"../x.png"}), "leaves the directory"));
  auto second = good();
  second.timestamp = 2.0;
  CHECK(contains(error({good(), second}, {"x.png", "./x.png"}), "frame 1: label image name './x.png' is also"));
  // Nothing was written.
  CHECK_FALSE(fs::exists(out));

  // A directory that cannot be created: its path is a file.
  const std::string file = dir.write("file", "x");
  const std::string e = error_of([&] { write_mask_directory(file + "/masks", {good()}); });
  CHECK(contains(e, "write_mask_directory: '" + file + "/masks': cannot create the directory"));
}

// ---- real data -------------------------------------------------------------------------

TEST_CASE("MaskDirectory reads shared/data/room_dyn_300/masks", "[io][masks][data]") {
  const std::string path = std::string(EMFUSION_SHARED_DATA_DIR) + "/room_dyn_300/masks";
  if (!fs::is_directory(path)) {
    WARN("room_dyn_300 masks test skipped: " << path << " not found");
    return;
  }
  MaskDirectory m = MaskDirectory::open(path, 640, 480);
  REQUIRE(m.size() == 10);
  for (std::size_t i = 0; i < m.size(); ++i) {
    CAPTURE(i);
    // Frames 0, 30, 60, ... of a 30 Hz sequence.
    CHECK(m.timestamp(i) == Approx(double(i)).margin(1e-9));
    char name[32];
    std::snprintf(name, sizeof(name), "%06zu.png", 30 * i);
    CHECK(fs::path(m.label_path(i)).filename() == name);
    const Detections d = m.read(i);
    CHECK(d.labels.same_size(640, 480));
    std::set<int> listed;
    for (const Instance& instance : d.instances) {
      listed.insert(instance.label);
      CHECK(instance.score >= 0.0);
      CHECK(instance.score <= 1.0);
      CHECK((instance.class_name == "cup" || instance.class_name == "book" || instance.class_name == "car"));
    }
    std::set<int> present;
    for (const std::uint16_t v : d.labels.to_host())
      if (v != 0) present.insert(v);
    for (const int v : present) CHECK(listed.count(v) == 1);
  }
  CHECK(m.instances(0).size() == 3);
  CHECK(m.instances(0)[0].class_name == "cup");
  CHECK(m.instances(0)[0].score == 0.924);
  // Frame 30 at 1.0 s (rgb timestamps are i / 30 with 6 decimals); frame 31 has no result.
  REQUIRE(m.detect(30, 1.0).has_value());
  CHECK_FALSE(m.detect(31, 1.033333).has_value());
}

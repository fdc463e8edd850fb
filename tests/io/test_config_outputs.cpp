// Parameters by name (config files, --set overrides) and the run outputs
// that have their own format (objects.txt): round trips and bad input that
// names the file, the line and the problem.
#include <string>
#include <vector>

#include "emfusion/io/config.hpp"
#include "emfusion/io/run_outputs.hpp"
#include "support/catch.hpp"
#include "support/files.hpp"

using namespace emfusion;
using emfusion::test::contains;
using emfusion::test::error_of;
using emfusion::test::ScratchDir;

TEST_CASE("Config files and overrides set parameters by name", "[io]") {
  ScratchDir dir;
  const std::string path = dir.write("a.conf", "# reference values, changed\nalpha = 0.7\n\n  max_objects=4  # cap\n"
                                               "static_classes = bed,oven\nuse_association = off\n");
  SystemParams<float> p;
  read_config(path, p);
  CHECK(p.likelihood.alpha == 0.7f);
  CHECK(p.max_objects == 4);
  CHECK(p.static_classes == std::vector<std::string>{"bed", "oven"});
  CHECK_FALSE(p.use_association);
  apply_override(p, "background_voxels=256");
  CHECK(p.background_voxels == 256);
  // Every entry prints a value that reads back to the same value.
  SystemParams<float> q;
  for (const auto& e : parameter_table<float>()) set_parameter(q, e.name, e.get(p));
  for (const auto& e : parameter_table<float>()) CHECK(e.get(q) == e.get(p));
  // A float prints as the text that reads back as it, as a user wrote it
  // (run.json's settings), not as its widened double's 0.699999988079071.
  for (const auto& e : parameter_table<float>()) {
    if (std::string(e.name) == "alpha") CHECK(e.get(p) == "0.7");
    if (std::string(e.name) == "bilateral_sigma_depth") CHECK(e.get(p) == "0.04");
    if (std::string(e.name) == "match_iou") CHECK(e.get(p) == "0.2");  // a double field
  }
}

TEST_CASE("static_classes and float parameters read back as they print", "[io]") {
  // Both found by tests/fuzz/fuzz_config.cpp: "a, b" kept the blank in " b"
  // (which no class name matches), and 1e300 became an infinite float that
  // validated but printed as "inf", which no config file can set.
  SystemParams<float> p;
  apply_override(p, "static_classes=person, dining_table ,,tv");
  CHECK(p.static_classes == std::vector<std::string>{"person", "dining_table", "tv"});
  apply_override(p, "static_classes= none");
  CHECK(p.static_classes.empty());
  apply_override(p, "static_classes=none,");
  CHECK(p.static_classes.empty());
  for (const auto& e : parameter_table<float>())
    if (std::string(e.name) == "static_classes") CHECK(e.get(p) == "none");
  CHECK_THROWS_WITH(apply_override(p, "sigma=1e300"), EMF_CONTAINS("sigma: '1e300' is out of range"));
  SystemParams<double> d;
  apply_override(d, "sigma=1e300");  // a double holds it (validation is read_config's business)
  CHECK(d.likelihood.sigma == 1e300);
}

TEST_CASE("Bad config files name the file, the line and the problem", "[io]") {
  ScratchDir dir;
  SystemParams<float> p;
  const auto bad = [&](const std::string& text) { return error_of([&] { read_config(dir.write("b.conf", text), p); }); };
  std::string e = bad("alpha = 0.8\nspeed = 3\n");
  CHECK(contains(e, "b.conf' line 2"));
  CHECK(contains(e, "unknown parameter 'speed'"));
  e = bad("\n\nsigma = wide\n");
  CHECK(contains(e, "line 3"));
  CHECK(contains(e, "sigma: 'wide' is not a number"));
  CHECK(contains(bad("alpha 0.8\n"), "expected 'key = value'"));
  CHECK(contains(bad("max_objects = 2.5\n"), "is not an integer"));
  CHECK(contains(bad("ignore_person = maybe\n"), "is not true or false"));
  e = bad("object_voxels = 4\n");  // read fine, rejected by validation
  CHECK(contains(e, "b.conf"));
  CHECK(contains(e, "object_voxels"));
  p = SystemParams<float>{};  // object_voxels = 4 stayed in p
  p = SystemParams<float>{};
  e = bad("object_pose_prior = -1\n");
  CHECK(contains(e, "b.conf"));
  CHECK(contains(e, "object_pose_prior must not be negative"));
  p = SystemParams<float>{};
  e = bad("reidentify_pose_prior = -0.5\n");
  CHECK(contains(e, "b.conf"));
  CHECK(contains(e, "reidentify_pose_prior must not be negative"));
  p = SystemParams<float>{};
  e = bad("background_unowned_free_from = 2\n");
  CHECK(contains(e, "b.conf"));
  CHECK(contains(e, "background_unowned_free_from must be in [0, 1]"));
  CHECK(contains(error_of([&] { read_config(dir.file("missing.conf"), p); }), "missing.conf"));
  CHECK(contains(error_of([&] { apply_override(p, "alpha"); }), "not of the form key=value"));
}

TEST_CASE("objects.txt round trip and bad lines", "[io]") {
  ScratchDir dir;
  const std::vector<ObjectListEntry> objects{{1, "cup", 0.0, 9.9666, false}, {7, "teddy_bear", 1.0, 2.5, true}};
  write_object_list(dir.file("objects.txt"), objects);
  const auto back = read_object_list(dir.file("objects.txt"));
  REQUIRE(back.size() == 2);
  CHECK(back[1].id == 7);
  CHECK(back[1].class_name == "teddy_bear");
  CHECK(back[0].last_timestamp == 9.9666);
  CHECK(back[1].deleted);
  CHECK(contains(error_of([&] { write_object_list(dir.file("x.txt"), {{2, "dining table", 0, 1, false}}); }),
                 "white space"));
  const std::string e = error_of([&] { read_object_list(dir.write("o.txt", "1 cup 0 1 0\n2 car 0 1 yes\n")); });
  CHECK(contains(e, "o.txt' line 2"));
  CHECK(contains(e, "deleted 'yes' is not 0 or 1"));
  CHECK(contains(error_of([&] { read_object_list(dir.write("p.txt", "1 cup 0 1\n")); }), "5 fields expected"));
}

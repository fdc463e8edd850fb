// Detection handling rules: mask IoU, matching with conflicts, depth groups
// and percentile boxes, volumetric IoU, static classes.
#include <cmath>
#include <cstdint>
#include <vector>

#include "emfusion/detect/matching.hpp"
#include "emfusion/detect/proposal.hpp"
#include "support/catch.hpp"

using namespace emfusion;
using emfusion::test::Approx;

namespace {

/// A w x h detection whose instance `label` covers the pixel rectangle
/// [x0, x1) x [y0, y1); several calls add instances.
void paint(Detections& d, int label, int x0, int y0, int x1, int y1) {
  auto px = d.labels.to_host();
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) px[std::size_t(y * d.labels.width() + x)] = std::uint16_t(label);
  d.labels = Image<std::uint16_t, Host>::from_host(d.labels.width(), d.labels.height(), px);
  d.instances.push_back({label, "cup", 0.9});
}

std::vector<int> rectangle_segmentation(int w, int h, int label, int x0, int y0, int x1, int y1,
                                        std::vector<int> seg = {}) {
  if (seg.empty()) seg.assign(std::size_t(w * h), 0);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) seg[std::size_t(y * w + x)] = label;
  return seg;
}

}  // namespace

TEST_CASE("Mask IoU counts overlapping pixels", "[detect]") {
  Detections d;
  d.labels = Image<std::uint16_t, Host>(20, 10, 0);
  paint(d, 7, 0, 0, 10, 10);                                     // 100 px
  const std::vector<int> seg = rectangle_segmentation(20, 10, 1, 5, 0, 15, 10);  // object 0: 100 px
  const auto iou = mask_iou(d, seg, 2);
  REQUIRE(iou.size() == 1);
  REQUIRE(iou[0].size() == 2);
  CHECK(iou[0][0] == Approx(50.0 / 150.0));
  CHECK(iou[0][1] == 0.0);  // object 1 is not rendered
  CHECK_THROWS_WITH(mask_iou(d, std::vector<int>(10, 0), 1), EMF_CONTAINS("pixels"));
}

TEST_CASE("Matching picks the higher IoU on conflicts and respects the threshold", "[detect]") {
  // Detection 0 overlaps object 0 with 0.4, detection 1 with 0.6: 1 wins.
  // Detection 2 overlaps object 1 with 0.15 only: below 0.2, unmatched.
  // Detection 3 overlaps object 1 with 0.3 and object 2 with 0.5: object 2.
  const std::vector<std::vector<double>> iou{
      {0.4, 0.0, 0.0}, {0.6, 0.1, 0.0}, {0.0, 0.15, 0.0}, {0.0, 0.3, 0.5}};
  const DetectionMatch m = match_detections(iou, 0.2);
  CHECK(m.object_of == std::vector<int>{-1, 0, -1, 2});
  CHECK(m.iou[1] == 0.6);
  CHECK(m.iou[0] == 0.0);
  // Ties go to the earlier detection, not to both.
  const DetectionMatch tie = match_detections({{0.5}, {0.5}}, 0.2);
  CHECK(tie.object_of == std::vector<int>{0, -1});
}

TEST_CASE("End to end: a detection of two overlapping candidates matches the better rendered mask", "[detect]") {
  Detections d;
  d.labels = Image<std::uint16_t, Host>(40, 20, 0);
  paint(d, 3, 0, 0, 20, 20);
  paint(d, 9, 18, 0, 40, 20);
  std::vector<int> seg = rectangle_segmentation(40, 20, 1, 0, 0, 16, 20);   // object 0 ~ instance 3
  seg = rectangle_segmentation(40, 20, 2, 16, 0, 40, 20, seg);              // object 1 ~ instance 9
  const DetectionMatch m = match_detections(mask_iou(d, seg, 2), 0.2);
  CHECK(m.object_of == std::vector<int>{0, 1});
}

TEST_CASE("Percentile boxes ignore the outer 10 percent and pad into cubes", "[detect]") {
  std::vector<Vec3<double>> pts;
  for (int i = 0; i <= 100; ++i) pts.push_back(vec3(double(i), 2.0 * i, 0.5));
  pts.push_back(vec3(1e6, -1e6, 1e6));  // a far outlier moves nothing much
  const Box<double> box = percentile_box(pts);
  CHECK(box.lo.x() == Approx(10).margin(1.01));
  CHECK(box.hi.x() == Approx(90).margin(1.01));
  CHECK(box.lo.y() == Approx(20).margin(2.01));
  CHECK(box.hi.y() == Approx(180).margin(2.01));
  const Box<double> cube = padded_cube(box, 2.0);
  CHECK(cube.hi.x() - cube.lo.x() == Approx(2.0 * box.largest_side()));
  CHECK(cube.center().y() == Approx(box.center().y()));
}

TEST_CASE("A mask's spill onto the surface behind is split off by depth", "[detect]") {
  // An object 1.30-1.45 m away seen by 700 pixels; the mask spills onto a
  // wall at 3 m with 300 more (30 %, enough to move the 90th percentile).
  std::vector<Vec3<double>> pts;
  for (int i = 0; i < 700; ++i) pts.push_back(vec3(0.001 * (i % 100), 0.001 * (i / 100), 1.3 + 0.15 * i / 699.0));
  for (int i = 0; i < 300; ++i) pts.push_back(vec3(0.002 * i, 0.1, 3.0 + 0.0005 * i));
  CHECK(percentile_box(pts).hi.z() > 2.9);  // what the percentiles alone would do
  const std::vector<Vec3<double>> object = largest_depth_group(pts, 0.1);
  REQUIRE(object.size() == 700);
  const Box<double> box = percentile_box(object);
  CHECK(box.hi.z() < 1.45);
  CHECK(box.lo.z() > 1.3);
  // A surface with no gap stays whole, however deep it is.
  std::vector<Vec3<double>> slanted;
  for (int i = 0; i < 500; ++i) slanted.push_back(vec3(0.0, 0.0, 1.0 + 0.004 * i));
  CHECK(largest_depth_group(slanted, 0.1).size() == 500);
  // Two equal groups: the nearer one. Fewer than two points: unchanged.
  const std::vector<Vec3<double>> pair = {vec3(0.0, 0.0, 2.0), vec3(0.0, 0.0, 1.0)};
  const auto nearer = largest_depth_group(pair, 0.1);
  REQUIRE(nearer.size() == 1);
  CHECK(nearer[0].z() == 1.0);
  CHECK(largest_depth_group(std::vector<Vec3<double>>{}, 0.1).empty());
}

TEST_CASE("Volumetric IoU of boxes", "[detect]") {
  const Vec3<double> one = Vec3<double>::constant(1.0);
  const SE3<double> I = SE3<double>::identity();
  CHECK(volume_iou(I, one, I, one) == Approx(1.0));
  CHECK(volume_iou(I, one, SE3<double>::translation(vec3(2.0, 0.0, 0.0)), one) == 0.0);
  // Half-shifted cubes: intersection 1/2, union 3/2.
  CHECK(volume_iou(I, one, SE3<double>::translation(vec3(0.5, 0.0, 0.0)), one) == Approx(1.0 / 3.0).margin(0.02));
  // A cube inside one twice its side: 1/8.
  CHECK(volume_iou(I, one, I, Vec3<double>::constant(2.0)) == Approx(1.0 / 8.0).margin(0.01));
}

TEST_CASE("Static classes are recognised with spaces or underscores", "[detect]") {
  const auto statics = default_static_classes();
  CHECK(is_listed_class("dining_table", statics));
  CHECK(is_listed_class("dining table", statics));
  CHECK(is_listed_class("refrigerator", statics));
  CHECK_FALSE(is_listed_class("cup", statics));
  CHECK_FALSE(is_listed_class("teddy_bear", statics));
}

// Work the volume kernels skip must be work that changes nothing: the
// frustum and far-plane range of an integrated voxel column, the silhouette
// guard's minimum filter, rays cast only where asked, up to a depth, and an
// object's rays marched only where its foreground is (majority_box).
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

#include "emfusion/volume/integrate.hpp"
#include "emfusion/volume/raycast.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/fusion.hpp"

using namespace emfusion;

TEMPLATE_TEST_CASE("A column's frustum range holds every voxel that projects into the image", "[volume]", float,
                   double) {
  using S = TestType;
  const PinholeCamera<S> camera{S(525), S(525), S(319.5), S(239.5), 640, 480};
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  const int nz = 200;
  const S voxel = S(0.02);
  int columns_with_voxels = 0, skipped = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const SE3<S> T = SE3<S>::exp(Vec6<S>{{S(2 * u(rng)), S(2 * u(rng)), S(2 * u(rng)), S(2 * u(rng)), S(2 * u(rng)),
                                          S(2 * u(rng))}});
    const Vec3<S> start = T * vec3(S(u(rng)), S(u(rng)), S(-2));
    const Vec3<S> step = T.rotate(vec3(S(0), S(0), voxel));
    const S far = trial % 2 ? S(2.5) : std::numeric_limits<S>::infinity();
    int z_begin = 0, z_end = nz;
    const bool any = detail::clip_column_to_frustum(camera, start, step, far, z_begin, z_end);
    bool inside_any = false;
    for (int z = 0; z < nz; ++z) {
      const Vec3<S> p = start + S(z) * step;
      if (!(p.z() > S(0)) || p.z() > far) continue;
      const Vec2<S> uv = camera.project(p);
      const int pu = int(std::floor(uv.x() + S(0.5))), pv = int(std::floor(uv.y() + S(0.5)));
      if (pu < 0 || pv < 0 || pu >= camera.width || pv >= camera.height) continue;
      inside_any = true;
      INFO("trial " << trial << ", voxel " << z << " projects to (" << pu << ", " << pv << ")");
      REQUIRE(any);
      REQUIRE(z >= z_begin);
      REQUIRE(z < z_end);
    }
    if (inside_any) ++columns_with_voxels;
    skipped += any ? nz - (z_end - z_begin) : nz;
  }
  // The test must see both kinds of column, and the range must cut work.
  CHECK(columns_with_voxels > 300);
  CHECK(skipped > 3000 * nz / 4);
}

TEMPLATE_TEST_CASE("max_valid_depth ignores holes, NaN and infinities", "[volume]", float, double) {
  using S = TestType;
  const S nan = std::numeric_limits<S>::quiet_NaN(), inf = std::numeric_limits<S>::infinity();
  const auto image = Image<S, Host>::from_host(3, 2, {S(1.5), nan, inf, S(-7), S(0), S(2.25)});
  CHECK(max_valid_depth(image) == S(2.25));
  CHECK(max_valid_depth(Image<S, Host>::from_host(2, 1, {S(0), nan})) == S(0));
}

TEMPLATE_TEST_CASE("The silhouette guard's minimum filter matches a direct search", "[volume]", float, double) {
  using S = TestType;
  const int w = 301, h = 23;  // wider than NearestDepthRows::chunk: three chunks a row
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<S> pixels(std::size_t(w) * h);
  for (S& d : pixels) {
    const double k = u(rng);
    d = k < 0.15 ? S(0) : k < 0.2 ? std::numeric_limits<S>::quiet_NaN() : k < 0.22 ? std::numeric_limits<S>::infinity()
                                                                                       : S(0.3 + 3 * u(rng));
  }
  const auto depth = Image<S, Host>::from_host(w, h, pixels);
  const S lateral = S(4);  // radius ceil(4 / d) pixels: 2 to 14 here
  for (const int dx : {0, 1}) {
    Image<S, Host> out(w, h, S(-1));
    for_each_index(Host{}, w * h,
                   detail::NearestDepthPass<S>{depth.view(), depth.view(), out.view(), lateral, dx, 1 - dx});
    const auto got = out.to_host();
    for (int v = 0; v < h; ++v)
      for (int x = 0; x < w; ++x) {
        const S d = pixels[std::size_t(v) * w + x];
        S nearest = is_valid_depth(d) ? d : S(0);
        if (is_valid_depth(d)) {
          const int radius = std::min(int(std::ceil(lateral / d)), 16);
          for (int k = -radius; k <= radius; ++k) {
            const int xx = x + k * dx, yy = v + k * (1 - dx);
            if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
            const S n = pixels[std::size_t(yy) * w + xx];
            if (is_valid_depth(n) && (nearest == S(0) || n < nearest)) nearest = n;
          }
        }
        INFO("pixel (" << x << ", " << v << "), pass along " << (dx ? "rows" : "columns"));
        REQUIRE(got[std::size_t(v) * w + x] == nearest);
      }
    // The CPU's row-chunked form (the system's path) gives the same values,
    // over the whole image and over a box (pixels outside it untouched).
    for (const PixelBox box : {PixelBox::whole(w, h), PixelBox{3, 2, 290, 19}}) {
      Image<S, Host> rows(w, h, S(-1));
      detail::nearest_depth_pass(Host{}, box,
                                 detail::NearestDepthPass<S>{depth.view(), depth.view(), rows.view(), lateral, dx, 1 - dx});
      const auto by_rows = rows.to_host();
      for (int v = 0; v < h; ++v)
        for (int x = 0; x < w; ++x) {
          INFO("pixel (" << x << ", " << v << "), box " << box.x0 << " " << box.y0 << " " << box.x1 << " " << box.y1);
          const std::size_t i = std::size_t(v) * w + x;
          REQUIRE(by_rows[i] == (box.contains(x, v) ? got[i] : S(-1)));
        }
    }
  }
}

namespace {
/// A sphere of 25 cm radius fused from 12 views around it into a 64^3 volume of 1 cm.
template <class S>
TsdfVolume<S, Host> fused_sphere() {
  sim::Scene<S> scene;
  scene.add(sim::make_sphere(Vec3<S>::zero(), S(0.25)));
  TsdfVolume<S, Host> volume(test::cube_around<S>(Vec3<S>::zero(), 64, S(0.01)));
  test::fuse_views(volume, scene, test::small_camera<S>(), test::orbit_poses<S>(Vec3<S>::zero(), S(1.2), 12));
  return volume;
}
}  // namespace

TEMPLATE_LIST_TEST_CASE("Rays cast only where asked and up to a depth find the full raycast's crossings before it",
                        "[volume]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const TsdfVolume<S, B> volume = fused_sphere<S>().template to<B>();
  const SE3<S> pose = sim::look_at<S>(vec3(S(0.8), S(-0.7), S(0.4)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)));
  RaycastResult<S, B> full, part;
  raycast(volume, camera, pose, full);
  const auto full_depth = full.depth.to_host();
  const auto full_hit = full.hit.to_host();

  // Left half: rays end 2 cm beyond the full raycast's depth on even rows
  // and 2 cm before it on odd rows (1.2 m where it missed); right half: none.
  std::vector<S> end(full_depth.size(), S(0));
  for (int v = 0; v < camera.height; ++v)
    for (int x = 0; x < camera.width / 2; ++x) {
      const std::size_t i = std::size_t(v) * camera.width + x;
      end[i] = full_hit[i] ? full_depth[i] + (v % 2 ? S(-0.02) : S(0.02)) : S(1.2);
    }
  const auto ray_end = Image<S, Host>::from_host(camera.width, camera.height, end).template to<B>();
  raycast(volume, camera, pose, part, {}, static_cast<const ForegroundCounts<S, B>*>(nullptr), &ray_end);

  const auto part_depth = part.depth.to_host();
  const auto part_hit = part.hit.to_host();
  std::size_t found = 0, cut = 0, outside = 0;
  for (int v = 0; v < camera.height; ++v)
    for (int x = 0; x < camera.width; ++x) {
      const std::size_t i = std::size_t(v) * camera.width + x;
      INFO("pixel (" << x << ", " << v << ")");
      if (x >= camera.width / 2 || !full_hit[i]) {
        REQUIRE(part_hit[i] == 0);
        REQUIRE(part_depth[i] == S(0));
        outside += full_hit[i];
      } else if (v % 2 == 0) {
        REQUIRE(part_hit[i] == 1);
        REQUIRE(part_depth[i] == full_depth[i]);
        ++found;
      } else {
        REQUIRE(part_hit[i] == 0);
        ++cut;
      }
    }
  CHECK(found > 500);
  CHECK(cut > 500);
  CHECK(outside > 1000);

  const auto wrong = Image<S, Host>(camera.width + 1, camera.height, S(1)).template to<B>();
  CHECK_THROWS_WITH(raycast(volume, camera, pose, part, {}, static_cast<const ForegroundCounts<S, B>*>(nullptr), &wrong),
                    EMF_CONTAINS("ray_end image is 201x150"));
}

namespace {
/// Foreground counts by voxel centre: Fg where x < x_fg (volume frame), Bg
/// elsewhere, every voxel counted once.
template <class S>
struct SlabCounts {
  ForegroundView<S, float> counts;
  S x_fg;
  EMF_HD void operator()(std::int64_t i) const {
    const S x = (S(i % counts.nx) + S(0.5)) * counts.voxel_size;
    counts.fg[i] = x < x_fg ? 1.0f : 0.0f;
    counts.bg[i] = x < x_fg ? 0.0f : 1.0f;
  }
};
}  // namespace

TEMPLATE_LIST_TEST_CASE("An object's rays march only near its foreground and draw what the whole march draws",
                        "[volume]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const auto camera = test::small_camera<S>();
  const TsdfVolume<S, B> volume = fused_sphere<S>().template to<B>();
  ForegroundCounts<S, B> counts(volume.dims(), volume.voxel_size());
  REQUIRE(counts.majority_box().empty());  // nothing counted: p_fg = 1/2 everywhere
  // The sphere's cap at x < -0.1 m (volume x < 0.22 m) is the object.
  for_each_index(B{}, std::int64_t(volume.voxel_count()), SlabCounts<S>{counts.view(), S(0.22)});
  const VoxelBox box = counts.majority_box();
  CHECK(box.lo[0] == 0);
  CHECK(box.hi[0] == 22);
  CHECK((box.lo[1] == 0 && box.hi[1] == 64 && box.lo[2] == 0 && box.hi[2] == 64));

  const SE3<S> pose = sim::look_at<S>(vec3(S(-0.9), S(-0.5), S(0.3)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)));
  RaycastParams<S> boxed, whole;
  boxed.min_foreground = S(0.5);      // p_fg > 1/2 only inside the majority box
  whole.min_foreground = S(0.49999);  // no box: every ray marches the whole grid
  RaycastResult<S, B> a, b;
  raycast(volume, camera, pose, a, boxed, &counts);
  raycast(volume, camera, pose, b, whole, &counts);
  const auto hit_a = a.hit.to_host(), hit_b = b.hit.to_host();
  const auto depth_a = a.depth.to_host(), depth_b = b.depth.to_host();
  std::size_t hits = 0, differ = 0;
  double worst = 0;
  for (std::size_t i = 0; i < hit_a.size(); ++i) {
    hits += hit_b[i];
    if (hit_a[i] != hit_b[i]) {
      ++differ;
      continue;
    }
    if (hit_a[i]) worst = std::max(worst, std::abs(double(depth_a[i]) - double(depth_b[i])));
  }
  CHECK(hits > 1000);
  CHECK(differ <= 2);  // a crossing exactly where p_fg lies in (0.49999, 0.5]
  CHECK(worst < 1e-4);  // another march phase: the same crossing, refined

  // Counts changed through a mutable view: the box is computed afresh.
  for_each_index(B{}, std::int64_t(volume.voxel_count()), SlabCounts<S>{counts.view(), S(1)});
  CHECK(counts.majority_box().hi[0] == 64);
  counts.reset();
  CHECK(counts.majority_box().empty());
  raycast(volume, camera, pose, a, boxed, &counts);
  const auto none = a.hit.to_host();
  CHECK(std::count(none.begin(), none.end(), std::uint8_t(1)) == 0);
}

TEMPLATE_LIST_TEST_CASE("Free space stored a few ulps below the truncation renders as free space", "[volume]",
                        emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  // Fusing the truncation distance many times leaves free-space voxels at
  // trunc or just below it; the raycast takes truncation-sized steps through
  // both (docs/benchmarks.md: a tenth of the steps) and must find the same
  // surfaces.
  const auto camera = test::small_camera<S>();
  const TsdfVolume<S, Host> fused = fused_sphere<S>();
  const S trunc = fused.truncation();
  const auto with_free_space = [&](S value) {
    TsdfVolume<S, Host> v = fused;
    auto view = v.view();
    std::size_t set = 0;
    for (std::int64_t i = 0; i < std::int64_t(v.dims()[0]) * v.dims()[1] * v.dims()[2]; ++i)
      if (view.weight[i] > S(0) && view.sdf[i] >= S(0.99) * trunc) view.sdf[i] = value, ++set;
    CHECK(set > 10000);
    return v.template to<B>();
  };
  const auto exact = with_free_space(trunc);
  const auto rounded = with_free_space(trunc * (S(1) - S(1e-5)));
  const SE3<S> pose = sim::look_at<S>(vec3(S(0.8), S(-0.7), S(0.4)), Vec3<S>::zero(), vec3(S(0), S(0), S(1)));
  const auto [depth_a, depth_b, hit_a, hit_b] = test::raycast_both(exact, rounded, camera, pose);
  std::size_t hits = 0;
  for (std::size_t i = 0; i < depth_a.size(); ++i) {
    INFO("pixel " << i);
    REQUIRE(hit_a[i] == hit_b[i]);
    REQUIRE(std::fabs(double(depth_a[i] - depth_b[i])) < 1e-4);
    hits += hit_a[i];
  }
  CHECK(hits > 1000);
}

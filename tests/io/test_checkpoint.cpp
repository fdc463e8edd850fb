// Checkpoints (io/checkpoint.hpp): a run saved, loaded into a new system and
// continued gives the poses of a run that never stopped (bit for bit on the
// CPU), a loaded map meshes like the saved one, and every damaged,
// foreign, newer or mismatched checkpoint is refused naming the file.
#include <bit>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "emfusion/io/checkpoint.hpp"
#include "emfusion/volume/marching_cubes.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/files.hpp"
#include "support/fusion.hpp"
#include "support/system_instances.hpp"

using namespace emfusion;
using emfusion::test::contains;
using emfusion::test::error_of;

namespace {

/// A wall 2 m ahead and a box in front of it, seen by a 160x120 camera that
/// moves 1 cm to the side per frame while the box moves 1 cm up; the box is
/// detected as a "cup" on even frames.
template <class S>
struct CheckpointScene {
  PinholeCamera<S> camera{S(140), S(140), S(79.5), S(59.5), 160, 120};

  SE3<S> camera_pose(int i) const { return SE3<S>::translation(vec3(S(0.01) * S(i), S(0), S(0))); }
  sim::Scene<S> scene(int i) const {
    sim::Scene<S> s;
    s.add(sim::make_plane(sim::look_at(vec3(S(0), S(0), S(2)), Vec3<S>::zero(), vec3(S(0), S(-1), S(0)))));
    s.add(sim::make_box(SE3<S>(so3_exp(vec3(S(0.2), S(0.4), S(0))), vec3(S(0), S(-0.01) * S(i), S(1.2))),
                        vec3(S(0.15), S(0.1), S(0.12))));
    return s;
  }
  /// The paper's tracking, or (`tracking_options`) with everything that keeps
  /// state between frames beyond the poses: motion prediction from the last
  /// two poses, retries from the other start, a depth pyramid and colour in
  /// the objects' models.
  static SystemParams<S> params(bool tracking_options = false, bool sparse = false) {
    SystemParams<S> p;
    p.background_voxels = 128;
    p.background_voxel_size = S(0.025);
    p.sparse_background = sparse;
    p.background_blocks = 1 << 12;
    p.predict_motion = tracking_options;
    p.retry_tracking = tracking_options;
    p.pyramid_levels = tracking_options ? 2 : 1;
    p.object_colour_weight = tracking_options ? S(10) : S(0);
    return p;
  }
  /// Frame i into `system`, with gray values: a ramp across the box, the
  /// rest dark.
  template <class B, class Sys>
  void feed(Sys& system, int i) const {
    Image<int, Host> labels;
    Image<S, Host> depth;
    sim::render_depth(scene(i), camera, camera_pose(i), depth, &labels);
    const double t = 0.1 * i;
    std::vector<S> gray;
    const std::vector<int> shape = labels.to_host();
    for (std::size_t k = 0; k < shape.size(); ++k)
      gray.push_back(shape[k] == 1 ? S(0.3) + S(0.5) * S(k % std::size_t(camera.width)) / S(camera.width) : S(0.2));
    const Image<S, B> intensity = Image<S, Host>::from_host(camera.width, camera.height, gray).template to<B>();
    if (i % 2 == 0) {
      Detections d;
      d.timestamp = t;
      std::vector<std::uint16_t> px;
      for (int l : labels.to_host()) px.push_back(std::uint16_t(l == 1 ? 5 : 0));
      d.labels = Image<std::uint16_t, Host>::from_host(labels.width(), labels.height(), px);
      d.instances.push_back({5, "cup", 0.95});
      system.process(depth.template to<B>(), t, &d, &intensity);
    } else {
      system.process(depth.template to<B>(), t, nullptr, &intensity);
    }
  }
};

double pose_diff(const SE3<double>& a, const SE3<double>& b) {
  double d = 0;
  for (int i = 0; i < 9; ++i) d = std::max(d, std::abs(a.rotation()[i] - b.rotation()[i]));
  for (int i = 0; i < 3; ++i) d = std::max(d, std::abs(a.translation()[i] - b.translation()[i]));
  return d;
}

/// The largest difference between two trajectories' poses (infinite if
/// their lengths or timestamps differ).
double max_abs_diff(const Trajectory& a, const Trajectory& b) {
  if (a.size() != b.size()) return INFINITY;
  double d = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    if (a[k].timestamp != b[k].timestamp) return INFINITY;
    d = std::max(d, pose_diff(a[k].pose, b[k].pose));
  }
  return d;
}

}  // namespace

TEMPLATE_LIST_TEST_CASE("Checkpoints: save, load, continue equals the uninterrupted run", "[io][checkpoint]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const CheckpointScene<S> scene;
  constexpr int first = 3, total = 7;
  const emfusion::test::ScratchDir dir;
  const std::string path = dir.file("run.emfckpt");
  const bool tracking_options = GENERATE(false, true);
  const bool sparse = GENERATE(false, true);
  INFO("motion prediction, retries and a pyramid: " << (tracking_options ? "on" : "off") << "; background "
                                                    << (sparse ? "sparse" : "dense"));
  const SystemParams<S> params = CheckpointScene<S>::params(tracking_options, sparse);

  System<S, B> straight(scene.camera, params);
  for (int i = 0; i < total; ++i) scene.template feed<B>(straight, i);

  {
    System<S, B> before(scene.camera, params);
    for (int i = 0; i < first; ++i) scene.template feed<B>(before, i);
    REQUIRE(!before.objects().empty());
    save_checkpoint(path, before);
    // Saving what was loaded gives the same bytes: nothing is lost or changed.
    const Checkpoint<S, B> loaded = load_checkpoint<S, B>(path);
    CHECK(checkpoint_bytes(loaded.map, loaded.camera) == emfusion::test::read_bytes(path));
  }
  System<S, B> resumed(scene.camera, params);
  restore_checkpoint(resumed, path);
  CHECK(resumed.frame_count() == first);
  CHECK(resumed.background().is_sparse() == sparse);
  for (int i = first; i < total; ++i) scene.template feed<B>(resumed, i);

  // Bit for bit on the CPU; the GPU's atomics sum in any order.
  const double tolerance = B::is_device ? 1e-6 : 0.0;
  CHECK(resumed.frame_count() == straight.frame_count());
  CHECK(max_abs_diff(resumed.camera_trajectory(), straight.camera_trajectory()) <= tolerance);
  REQUIRE(resumed.object_records().size() == straight.object_records().size());
  REQUIRE(!straight.object_records().empty());
  for (std::size_t k = 0; k < straight.object_records().size(); ++k) {
    const ObjectRecord &a = resumed.object_records()[k], &b = straight.object_records()[k];
    CHECK(a.id == b.id);
    CHECK(a.class_name == b.class_name);
    CHECK(a.deleted == b.deleted);
    CHECK(max_abs_diff(a.trajectory, b.trajectory) <= tolerance);
  }
  REQUIRE(resumed.objects().size() == straight.objects().size());
  for (std::size_t k = 0; k < straight.objects().size(); ++k)
    CHECK(resumed.objects()[k]->colour().empty() == !tracking_options);
  for (std::size_t k = 0; k < straight.objects().size(); ++k)
    CHECK(pose_diff(resumed.objects()[k]->pose().template cast<double>(),
                    straight.objects()[k]->pose().template cast<double>()) <= tolerance);
  if constexpr (!B::is_device)
    CHECK(checkpoint_bytes(resumed.map(), resumed.camera()) == checkpoint_bytes(straight.map(), straight.camera()));
}

TEMPLATE_LIST_TEST_CASE("Checkpoints: a loaded map meshes without the sequence", "[io][checkpoint]",
                        emfusion::test::HeavyConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const CheckpointScene<S> scene;
  const emfusion::test::ScratchDir dir;
  const bool sparse = GENERATE(false, true);
  INFO("background " << (sparse ? "sparse" : "dense"));
  System<S, B> system(scene.camera, scene.params(false, sparse));
  for (int i = 0; i < 2; ++i) scene.template feed<B>(system, i);
  save_checkpoint(dir.file("a.emfckpt"), system);
  const Checkpoint<S, B> ck = load_checkpoint<S, B>(dir.file("a.emfckpt"));
  REQUIRE(ck.map.background.is_sparse() == sparse);
  const auto mesh = [](const BackgroundVolume<S, B>& b) {
    return b.visit([](const auto& v) { return marching_cubes(v, S(0), S(1)); });
  };
  const auto before = mesh(system.background()), after = mesh(ck.map.background);
  REQUIRE(after.vertices.size() == before.vertices.size());
  CHECK(!after.vertices.empty());
  std::size_t differing = 0;  // the same voxels in the same order: the same mesh, bit for bit
  for (std::size_t k = 0; k < after.vertices.size(); ++k)
    for (int a = 0; a < 3; ++a) differing += after.vertices[k][a] != before.vertices[k][a];
  CHECK(differing == 0);
  if (sparse) {
    const auto keys = [](const SparseTsdfVolume<S, B>& v) {
      std::vector<std::uint64_t> out;
      for (const Vec3i& c : v.blocks_to_host()) out.push_back(detail::sparse::pack_key(c[0], c[1], c[2]));
      return out;
    };
    CHECK(keys(*ck.map.background.sparse()) == keys(*system.background().sparse()));
    CHECK(ck.map.background.sparse()->capacity() == system.background().sparse()->capacity());
  }
  REQUIRE(ck.map.objects.size() == system.objects().size());
  for (std::size_t k = 0; k < ck.map.objects.size(); ++k)
    CHECK(marching_cubes(ck.map.objects[k]->volume(), S(0), S(1)).vertices.size() ==
          marching_cubes(system.objects()[k]->volume(), S(0), S(1)).vertices.size());
  // The saved voxels, not a dense dump: unobserved voxels compress away
  // (a sparse background holds few of them to begin with).
  CHECK(emfusion::test::read_bytes(dir.file("a.emfckpt")).size() < system.memory_bytes() / (sparse ? 2 : 10));
}

TEST_CASE("Checkpoints: damaged, foreign, newer and mismatched checkpoints are refused", "[io][checkpoint]") {
  using S = float;
  const CheckpointScene<S> scene;
  const emfusion::test::ScratchDir dir;
  System<S> system(scene.camera, scene.params());
  for (int i = 0; i < 2; ++i) scene.template feed<Host>(system, i);
  const std::string good = dir.file("good.emfckpt");
  save_checkpoint(good, system);
  const std::string bytes = emfusion::test::read_bytes(good);
  REQUIRE(bytes.size() > 100);

  const std::string bad = dir.file("bad.emfckpt");
  const auto refusal = [&](const std::string& content) {
    emfusion::test::write_bytes(bad, content);
    const std::string e = error_of([&] { (void)load_checkpoint<S>(bad); });
    CHECK(contains(e, bad));
    return e;
  };
  for (std::size_t n : {std::size_t(0), std::size_t(5), std::size_t(8), std::size_t(20), std::size_t(24),
                        std::size_t(60), bytes.size() / 2, bytes.size() - 4, bytes.size() - 1})
    CHECK(contains(refusal(bytes.substr(0, n)), n < 8 ? "not an emfusion checkpoint" : "truncated"));
  CHECK(contains(refusal(bytes + "x"), "follow the checksum"));
  for (std::size_t at : {std::size_t(30), bytes.size() / 3, bytes.size() - 10}) {
    std::string flipped = bytes;
    flipped[at] = char(flipped[at] ^ 0x10);
    CHECK(contains(refusal(flipped), "checksum mismatch"));
  }
  std::string crc = bytes;  // the stored checksum itself damaged
  crc.back() = char(crc.back() ^ 1);
  CHECK(contains(refusal(crc), "checksum mismatch"));
  std::string foreign = bytes;
  foreign[0] = 'P';
  CHECK(contains(refusal(foreign), "not an emfusion checkpoint"));
  CHECK(contains(refusal("ply\nformat ascii 1.0\n"), "not an emfusion checkpoint"));
  std::string newer = bytes;
  newer[8] = char(checkpoint_version + 1);
  CHECK(contains(refusal(newer), "version " + std::to_string(checkpoint_version + 1) + " is not supported"));
  // Versions 1 (a dense background without its kind byte), 2 (no hidden
  // times of the records), 3 (no colour flags at the end) and 4 (no held
  // flags of lost objects) are still read,
  // and an unknown kind is refused: payloads rebuilt with a right checksum.
  const auto rebuilt = [&](std::uint32_t version, const std::string& payload) {
    std::string out = bytes.substr(0, 8);
    detail::bytes::put_u32(out, version);
    out += bytes.substr(12, 4);
    detail::bytes::put_u64(out, payload.size());
    out += payload;
    detail::bytes::put_u32(out, detail::checkpoint::crc32_of(reinterpret_cast<const unsigned char*>(payload.data()),
                                                              payload.size()));
    return out;
  };
  const std::string payload = bytes.substr(24, bytes.size() - 28);
  const std::size_t records = system.map().records.size();
  REQUIRE(records > 0);
  // Version 4 ends with a colour flag per object (0: none in this system).
  const std::size_t colour_flags = system.map().objects.size() + system.map().lost.size();
  REQUIRE(colour_flags > 0);
  REQUIRE(payload.substr(payload.size() - colour_flags) == std::string(colour_flags, '\0'));
  const std::string v3_payload = payload.substr(0, payload.size() - colour_flags);
  const std::string v2_payload = v3_payload.substr(0, v3_payload.size() - 8 * records);
  std::string kind_and_dims;  // the kind byte (0, dense), then the background's dimensions
  kind_and_dims += '\0';
  for (int a = 0; a < 3; ++a) detail::bytes::put_i32(kind_and_dims, 128);
  const std::size_t kind_at = payload.find(kind_and_dims);
  REQUIRE(kind_at != std::string::npos);
  REQUIRE(payload.find(kind_and_dims, kind_at + 1) == std::string::npos);
  const std::string v1 = dir.file("v1.emfckpt");
  emfusion::test::write_bytes(v1, rebuilt(1, v2_payload.substr(0, kind_at) + v2_payload.substr(kind_at + 1)));
  const Checkpoint<S> old = load_checkpoint<S>(v1);
  REQUIRE(old.map.background.dense() != nullptr);
  CHECK(checkpoint_bytes(old.map, old.camera) == bytes);  // no object was held hidden: NaN times
  const std::string v2 = dir.file("v2.emfckpt");
  emfusion::test::write_bytes(v2, rebuilt(2, v2_payload));
  const Checkpoint<S> two = load_checkpoint<S>(v2);
  CHECK(checkpoint_bytes(two.map, two.camera) == bytes);
  const std::string v3 = dir.file("v3.emfckpt");
  emfusion::test::write_bytes(v3, rebuilt(3, v3_payload));
  const Checkpoint<S> three = load_checkpoint<S>(v3);
  CHECK(checkpoint_bytes(three.map, three.camera) == bytes);  // no colour
  // The records' hidden times: the last record's, set, comes back; an
  // infinite one is refused, and so are bytes after them.
  const auto with_last_time = [&](double t) {
    std::string p = payload;
    std::string v;
    detail::bytes::put_u64(v, std::bit_cast<std::uint64_t>(t));
    p.replace(p.size() - colour_flags - 8, 8, v);
    return rebuilt(checkpoint_version, p);
  };
  emfusion::test::write_bytes(bad, with_last_time(1.25));
  CHECK(load_checkpoint<S>(bad).map.records.back().hidden_since == 1.25);
  CHECK(contains(refusal(with_last_time(INFINITY)), "infinite hidden time"));
  CHECK(contains(refusal(rebuilt(3, v3_payload + "12345678")), "bytes follow the records' hidden times"));
  // No lost object here, so version 5 adds no held flags to version 4.
  REQUIRE(system.map().lost.empty());
  CHECK(contains(refusal(rebuilt(4, payload + "12345678")), "bytes follow the objects' colour"));
  CHECK(contains(refusal(rebuilt(checkpoint_version, payload + "12345678")),
                 "bytes follow the lost objects' held flags"));
  {
    // Version 5: a lost object's held flag comes back; a flag other than
    // 0 or 1 is refused, and a version 4 file is read with none held.
    Checkpoint<S> state = load_checkpoint<S>(good);
    REQUIRE(state.map.objects.size() == 1);
    state.map.lost.push_back(LostObject<S, Host>{std::move(state.map.objects[0]), 1, true});
    state.map.objects.clear();
    const std::string held_bytes = checkpoint_bytes(state.map, state.camera);
    emfusion::test::write_bytes(bad, held_bytes);
    const Checkpoint<S> held = load_checkpoint<S>(bad);
    REQUIRE(held.map.lost.size() == 1);
    CHECK(held.map.lost[0].held_detection);
    CHECK(checkpoint_bytes(held.map, held.camera) == held_bytes);
    const std::string held_payload = held_bytes.substr(24, held_bytes.size() - 28);
    REQUIRE(held_payload.back() == 1);
    std::string two = held_payload;
    two.back() = 2;
    CHECK(contains(refusal(rebuilt(checkpoint_version, two)), "a lost object's held flag must be 0 or 1, got 2"));
    emfusion::test::write_bytes(bad, rebuilt(4, held_payload.substr(0, held_payload.size() - 1)));
    const Checkpoint<S> four = load_checkpoint<S>(bad);
    REQUIRE(four.map.lost.size() == 1);
    CHECK_FALSE(four.map.lost[0].held_detection);
  }
  // A colour flag other than 0 or 1, and a colour that is not there.
  std::string flag = payload;
  flag.back() = 2;
  CHECK(contains(refusal(rebuilt(checkpoint_version, flag)), "an object's colour flag must be 0 or 1, got 2"));
  flag.back() = 1;
  CHECK(contains(refusal(rebuilt(checkpoint_version, flag)), "an object's gray values"));
  std::string unknown_kind = payload;
  unknown_kind[kind_at] = 2;
  CHECK(contains(refusal(rebuilt(checkpoint_version, unknown_kind)), "unknown background kind 2"));
  std::string odd_scalar = bytes;
  odd_scalar[12] = 3;
  CHECK(contains(refusal(odd_scalar), "unknown scalars"));
  // A float checkpoint read as double.
  const std::string e = error_of([&] { (void)load_checkpoint<double>(good); });
  CHECK(contains(e, good));
  CHECK(contains(e, "a checkpoint of float scalars"));
  CHECK(contains(error_of([&] { (void)load_checkpoint<S>(dir.file("missing.emfckpt")); }), "missing.emfckpt"));

  // A system of another camera or another background grid: refused, unchanged.
  PinholeCamera<S> other_camera = scene.camera;
  other_camera.fx = S(150);
  System<S> other(other_camera, scene.params());
  CHECK(contains(error_of([&] { restore_checkpoint(other, good); }), "saved with camera 160x120 fx 140"));
  SystemParams<S> other_params = scene.params();
  other_params.background_voxels = 64;
  System<S> coarse(scene.camera, other_params);
  const std::string grid = error_of([&] { restore_checkpoint(coarse, good); });
  CHECK(contains(grid, good));
  CHECK(contains(grid, "128x128x128 voxels"));
  CHECK(coarse.frame_count() == 0);
}

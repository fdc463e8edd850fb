// Writes the seeds of tests/fuzz/corpus/checkpoint/: small checkpoints (an
// 8^3 background, or a sparse one of two blocks; a live and a lost object
// of 4^3 voxels, records with trajectories) of float and double maps, and
// damaged copies that stop in
// each of the reader's checks (truncated, checksum, newer version, trailing
// bytes). Run by hand from the repository root after changing the format:
//
//   c++ -std=c++20 -Iinclude -I<thrust> -DTHRUST_DEVICE_SYSTEM=THRUST_DEVICE_SYSTEM_CPP
//       tests/fuzz/make_checkpoint_seeds.cpp -lz -o /tmp/make_checkpoint_seeds
//
// (one command; <thrust> is the thrust include directory CMake reports,
// e.g. /usr/local/cuda/include/cccl)
//   /tmp/make_checkpoint_seeds tests/fuzz/corpus/checkpoint
#include <cstdio>
#include <fstream>
#include <string>

#include "emfusion/io/checkpoint.hpp"

namespace {

using namespace emfusion;

template <class S>
std::string small_checkpoint(bool sparse = false) {
  SystemParams<S> p;
  p.background_voxels = 8;
  p.background_voxel_size = S(0.1);
  p.sparse_background = sparse;
  p.background_blocks = 4;
  Map<S> map(p);
  // A few observed voxels, so that the streams are not all alike.
  if (sparse) {
    std::vector<S> sdf(2 * 512, S(1)), weight(2 * 512, S(0));
    for (int i = 0; i < 64; ++i) sdf[std::size_t(i)] = S(0.01) * S(i % 7), weight[std::size_t(i)] = S(1 + i % 3);
    map.background.sparse()->assign_from_host({Vec3i{{0, 0, 1}}, Vec3i{{-1, 0, 1}}}, sdf, weight);
  } else {
    TsdfVolume<S, Host>& background = *map.background.dense();
    std::vector<S> sdf = background.sdf_to_host(), weight = background.weight_to_host();
    for (int i = 0; i < 64; ++i) sdf[std::size_t(i)] = S(0.01) * S(i % 7), weight[std::size_t(i)] = S(1 + i % 3);
    background.assign_from_host(sdf, weight);
  }
  for (int id : {1, 2}) {
    auto o = std::make_unique<ObjectModel<S>>(id, "cup", SE3<S>::translation(vec3(S(0.1) * S(id), S(0), S(1))), 4,
                                              S(0.02), S(3));
    o->add_class_score("cup", 0.9);
    o->add_class_score("bowl", 0.4);
    o->count_missed();
    ObjectRecord r;
    r.id = id;
    r.class_name = "cup";
    r.first_timestamp = 0.0, r.last_timestamp = 0.1;
    r.trajectory = {{0.0, o->pose().template cast<double>()}, {0.1, o->pose().template cast<double>()}};
    if (id == 2) {
      r.deleted = true, r.reason = DeletionReason::not_visible;
      map.lost.push_back({std::move(o), 1});
    } else {
      map.objects.push_back(std::move(o));
    }
    map.records.push_back(r);
  }
  map.young = {1};
  map.next_id = 3;
  map.frames = 2;
  map.started = true;
  map.camera_trajectory = {{0.0, SE3<double>::identity()}, {0.1, SE3<double>::translation(vec3(0.01, 0.0, 0.0))}};
  map.T_world_camera = SE3<S>::translation(vec3(S(0.01), S(0), S(0)));
  return checkpoint_bytes(map, PinholeCamera<S>{S(3), S(3), S(1.5), S(1), 4, 3});
}

void write(const std::string& dir, const std::string& name, const std::string& bytes) {
  std::ofstream(dir + "/" + name, std::ios::binary) << bytes;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_checkpoint_seeds <directory>\n");
    return 2;
  }
  const std::string dir = argv[1];
  const std::string f = small_checkpoint<float>(), d = small_checkpoint<double>();
  write(dir, "float_map.emfckpt", f);
  write(dir, "double_map.emfckpt", d);
  write(dir, "float_sparse_map.emfckpt", small_checkpoint<float>(true));
  // float_map_v1.emfckpt and float_map_v2.emfckpt beside them are the
  // same map in format versions 1 and 2 (written by this program before
  // versions 2 and 3), kept so that the fuzzer starts from the older
  // layouts too.
  write(dir, "truncated.emfckpt", f.substr(0, f.size() / 2));
  std::string flipped = f;
  flipped[f.size() / 2] = char(flipped[f.size() / 2] ^ 0x40);
  write(dir, "checksum_mismatch.emfckpt", flipped);
  std::string newer = f;
  newer[8] = char(checkpoint_version + 1);
  write(dir, "newer_version.emfckpt", newer);
  write(dir, "trailing_bytes.emfckpt", f + "more");
  return 0;
}

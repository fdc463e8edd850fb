// Checkpoints: the whole state of a System (its Map: background and object
// volumes, foreground counts, the objects' colour, poses, existence, class scores, lost objects,
// trajectories, records, the frame count; a dense or a sparse background)
// and its camera in one binary file,
// so that a run can stop and go on later with the same poses, and meshes of
// a saved map can be extracted without the sequence. The format is in
// docs/io.md, "Checkpoints": a header with a version and the scalar size, a
// CRC-32 of the payload, volumes as zlib streams (unobserved voxels are all
// alike and compress to almost nothing).
//
// The reader trusts nothing: a truncated, corrupt, foreign or newer file,
// a checkpoint of the other scalar, or sizes that do not add up are refused
// with std::runtime_error naming the file, before anything is allocated
// from a size the file claims beyond what its bytes can hold.
#pragma once

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <zlib.h>

#include "emfusion/core/camera.hpp"
#include "emfusion/io/detail/bytes.hpp"
#include "emfusion/io/detail/files.hpp"
#include "emfusion/io/detail/zlib.hpp"
#include "emfusion/slam/map.hpp"
#include "emfusion/slam/system.hpp"

namespace emfusion {

/// The version save_checkpoint writes; the reader refuses newer ones.
/// Version 1 held a dense background only; version 2 says which kind it is;
/// version 3 adds the records' hidden times (ObjectRecord::hidden_since);
/// version 4 the objects' colour (ObjectModel::colour); version 5 whether
/// each lost object held a detection (LostObject::held_detection).
inline constexpr std::uint32_t checkpoint_version = 5;
/// The first 8 bytes of every checkpoint.
inline constexpr char checkpoint_magic[8] = {'E', 'M', 'F', 'C', 'K', 'P', 'T', '\0'};

/// A loaded checkpoint: the camera it was made with and the map.
template <class S, Backend B = Host>
struct Checkpoint {
  PinholeCamera<S> camera;
  Map<S, B> map;
};

namespace detail::checkpoint {

constexpr std::size_t header_bytes = 24;  // magic, version, scalar size, 3 reserved, payload size
constexpr std::size_t crc_bytes = 4;
// No zlib stream inflates by more than about 1032:1; a claimed size beyond
// this many times the stream's bytes is a lie, refused before allocating.
constexpr std::size_t max_inflation = 1100;

inline std::uint32_t crc32_of(const unsigned char* p, std::size_t n) {
  uLong crc = ::crc32(0L, Z_NULL, 0);
  while (n > 0) {
    const uInt chunk = uInt(std::min<std::size_t>(n, std::size_t(1) << 30));
    crc = ::crc32(crc, p, chunk);
    p += chunk, n -= chunk;
  }
  return std::uint32_t(crc);
}

/// Little-endian bytes of `n` values (the host order is swapped on a
/// big-endian machine).
template <class T>
std::vector<unsigned char> le_bytes(const std::vector<T>& v) {
  std::vector<unsigned char> out(v.size() * sizeof(T));
  if (!out.empty()) std::memcpy(out.data(), v.data(), out.size());
  if constexpr (std::endian::native == std::endian::big)
    for (std::size_t i = 0; i < out.size(); i += sizeof(T)) std::reverse(out.begin() + i, out.begin() + i + sizeof(T));
  return out;
}
template <class T>
std::vector<T> from_le_bytes(std::vector<unsigned char>& bytes) {
  if constexpr (std::endian::native == std::endian::big)
    for (std::size_t i = 0; i < bytes.size(); i += sizeof(T))
      std::reverse(bytes.begin() + i, bytes.begin() + i + sizeof(T));
  std::vector<T> out(bytes.size() / sizeof(T));
  if (!out.empty()) std::memcpy(out.data(), bytes.data(), out.size() * sizeof(T));
  return out;
}

class Writer {
 public:
  std::string out;

  void u8(unsigned v) { bytes::put_u8(out, v); }
  void i32(int v) { bytes::put_i32(out, std::int32_t(v)); }
  void u64(std::uint64_t v) { bytes::put_u64(out, v); }
  void f64(double v) { bytes::put_u64(out, std::bit_cast<std::uint64_t>(v)); }
  template <class S>
  void scalar(S v) {
    if constexpr (sizeof(S) == 4) bytes::put_u32(out, std::bit_cast<std::uint32_t>(v));
    else bytes::put_u64(out, std::bit_cast<std::uint64_t>(v));
  }
  void string(const std::string& s) {
    bytes::put_u32(out, std::uint32_t(s.size()));
    out += s;
  }
  template <class S>
  void pose(const SE3<S>& T) {
    for (int i = 0; i < 9; ++i) scalar(T.rotation()[i]);
    for (int i = 0; i < 3; ++i) scalar(T.translation()[i]);
  }
  void trajectory(const Trajectory& t) {
    u64(t.size());
    for (const TimedPose& p : t) {
      f64(p.timestamp);
      pose(p.pose);
    }
  }
  /// One zlib stream of `raw`: its size in bytes, then the stream.
  void compressed(const std::vector<unsigned char>& raw) {
    const std::vector<unsigned char> z = zlib::deflate(raw.data(), raw.size(), Z_BEST_SPEED);
    u64(z.size());
    out.append(reinterpret_cast<const char*>(z.data()), z.size());
  }
  template <class S, Backend B>
  void volume(const TsdfVolume<S, B>& v) {
    for (int a = 0; a < 3; ++a) i32(v.dims()[a]);
    scalar(v.voxel_size());
    scalar(v.truncation());
    pose(v.pose());
    compressed(le_bytes(v.sdf_to_host()));
    compressed(le_bytes(v.weight_to_host()));
  }
  template <class S, Backend B>
  void sparse_volume(const SparseTsdfVolume<S, B>& v) {
    scalar(v.voxel_size());
    scalar(v.truncation());
    pose(v.pose());
    i32(v.capacity());
    const std::vector<Vec3i> blocks = v.blocks_to_host();
    u64(blocks.size());
    std::vector<std::int32_t> coordinates(3 * blocks.size());
    for (std::size_t b = 0; b < blocks.size(); ++b)
      for (int a = 0; a < 3; ++a) coordinates[3 * b + std::size_t(a)] = blocks[b][a];
    const std::vector<unsigned char> raw = le_bytes(coordinates);
    compressed(raw);
    compressed(le_bytes(v.sdf_to_host()));
    compressed(le_bytes(v.weight_to_host()));
  }
  /// The background: its kind (0 dense, 1 sparse), then the volume.
  template <class S, Backend B>
  void background(const BackgroundVolume<S, B>& background) {
    if (const auto* dense = background.dense()) {
      u8(0);
      volume(*dense);
    } else {
      u8(1);
      sparse_volume(*background.sparse());
    }
  }
  template <class S, Backend B>
  void object(const ObjectModel<S, B>& o) {
    i32(o.id());
    string(o.class_name());
    u64(o.class_scores().size());
    for (const auto& [name, score] : o.class_scores()) {
      string(name);
      f64(score);
    }
    pose(o.pose());
    pose(o.T_object_volume());
    i32(o.existence_count());
    i32(o.non_existence_count());
    volume(o.volume());
    compressed(le_bytes(o.foreground().fg_to_host()));
    compressed(le_bytes(o.foreground().bg_to_host()));
  }
  /// Version 4: whether the object has colour, and then its gray values
  /// and colour weights.
  template <class S, Backend B>
  void colour(const ObjectModel<S, B>& o) {
    u8(o.colour().empty() ? 0 : 1);
    if (o.colour().empty()) return;
    compressed(le_bytes(o.colour().values_to_host()));
    compressed(le_bytes(o.colour().weights_to_host()));
  }
};

/// Reads fields of the payload; every problem is an error naming the file.
class Reader {
 public:
  Reader(const unsigned char* p, std::size_t n, std::string source) : p_(p), end_(p + n), source_(std::move(source)) {}

  [[noreturn]] void fail(const std::string& problem) const {
    throw std::runtime_error("load_checkpoint: " + io::quoted(source_) + ": " + problem);
  }
  std::size_t left() const { return std::size_t(end_ - p_); }
  const unsigned char* take(std::size_t n, const char* what) {
    if (n > left())
      fail(std::string("the payload ends inside ") + what + " (" + std::to_string(n) + " bytes needed, " +
           std::to_string(left()) + " left)");
    const unsigned char* at = p_;
    p_ += n;
    return at;
  }
  unsigned u8(const char* what) { return *take(1, what); }
  bool flag(const char* what) {
    const unsigned v = u8(what);
    if (v > 1) fail(std::string(what) + " must be 0 or 1, got " + std::to_string(v));
    return v == 1;
  }
  int i32(const char* what) { return bytes::i32(take(4, what)); }
  std::uint64_t u64(const char* what) { return bytes::u64(take(8, what)); }
  double f64(const char* what) { return std::bit_cast<double>(bytes::u64(take(8, what))); }
  template <class S>
  S scalar(const char* what) {
    if constexpr (sizeof(S) == 4) return std::bit_cast<S>(bytes::u32(take(4, what)));
    else return std::bit_cast<S>(bytes::u64(take(8, what)));
  }
  template <class S>
  S finite(const char* what) {
    const S v = scalar<S>(what);
    if (!std::isfinite(double(v))) fail(std::string(what) + " is not finite");
    return v;
  }
  std::string string(const char* what) {
    const std::uint32_t n = bytes::u32(take(4, what));
    const unsigned char* s = take(n, what);
    return std::string(reinterpret_cast<const char*>(s), n);
  }
  /// A count of items of at least `min_bytes` each: no more than the bytes left can hold.
  std::size_t count(const char* what, std::size_t min_bytes) {
    const std::uint64_t n = u64(what);
    if (n > left() / min_bytes)
      fail(std::string(what) + " claims " + std::to_string(n) + " entries, more than the " + std::to_string(left()) +
           " bytes left can hold");
    return std::size_t(n);
  }
  template <class S>
  SE3<S> pose(const char* what) {
    SE3<S> T;
    for (int i = 0; i < 9; ++i) T.rotation()[i] = finite<S>(what);
    for (int i = 0; i < 3; ++i) T.translation()[i] = finite<S>(what);
    return T;
  }
  Trajectory trajectory(const char* what) {
    Trajectory t(count(what, 8 + 12 * 8));
    for (TimedPose& p : t) {
      p.timestamp = f64(what);
      p.pose = pose<double>(what);
    }
    return t;
  }
  /// A zlib stream that must inflate to `values` values of T.
  template <class T>
  std::vector<T> compressed(std::size_t values, const char* what) {
    const std::uint64_t size = u64(what);
    const unsigned char* z = take(std::size_t(std::min<std::uint64_t>(size, left() + 1)), what);
    const std::size_t raw = values * sizeof(T);
    if (raw / max_inflation > size)
      fail(std::string(what) + ": " + std::to_string(size) + " compressed bytes cannot hold " + std::to_string(raw));
    std::vector<unsigned char> bytes;
    const std::string problem = zlib::inflate_exact(z, std::size_t(size), raw, bytes);
    if (!problem.empty()) fail(std::string(what) + ": " + problem);
    return from_le_bytes<T>(bytes);
  }
  /// A volume's grid: dimensions 1..4096 each, positive voxel size and
  /// truncation.
  template <class S>
  VolumeGeometry<S> geometry(const char* what) {
    VolumeGeometry<S> g;
    for (int a = 0; a < 3; ++a) {
      g.dims[a] = i32(what);
      if (g.dims[a] < 1 || g.dims[a] > 4096)
        fail(std::string(what) + ": dimension " + std::to_string(g.dims[a]) + " outside 1..4096");
    }
    g.voxel_size = finite<S>(what);
    g.truncation = finite<S>(what);
    if (!(g.voxel_size > S(0)) || !(g.truncation > S(0)))
      fail(std::string(what) + ": the voxel size and the truncation must be positive");
    g.T_world_volume = pose<S>(what);
    return g;
  }
  template <class S, Backend B>
  TsdfVolume<S, B> volume(const char* what, const B& backend) {
    const VolumeGeometry<S> g = geometry<S>(what);
    const std::size_t n = std::size_t(g.dims[0]) * std::size_t(g.dims[1]) * std::size_t(g.dims[2]);
    // Both streams first: a lying stream must not cost a volume's allocation.
    std::vector<S> sdf = compressed<S>(n, what);
    std::vector<S> weight = compressed<S>(n, what);
    TsdfVolume<S, B> v(g, backend);
    v.assign_from_host(sdf, weight);
    return v;
  }
  /// A sparse volume: capacity 1..2^26 blocks (SparseTsdfVolume's limit),
  /// no more blocks than that, each once and in range.
  template <class S, Backend B>
  SparseTsdfVolume<S, B> sparse_volume(const char* what, const B& backend) {
    SparseVolumeParams<S> params;
    params.voxel_size = finite<S>(what);
    params.truncation = finite<S>(what);
    if (!(params.voxel_size > S(0)) || !(params.truncation > S(0)))
      fail(std::string(what) + ": the voxel size and the truncation must be positive");
    params.T_world_volume = pose<S>(what);
    params.block_capacity = i32(what);
    constexpr int max_capacity = SparseTsdfVolume<S, B>::max_block_capacity;
    if (params.block_capacity < 1 || params.block_capacity > max_capacity)
      fail(std::string(what) + ": block capacity " + std::to_string(params.block_capacity) + " outside 1.." +
           std::to_string(max_capacity));
    const std::uint64_t n = u64(what);
    if (n > std::uint64_t(params.block_capacity))
      fail(std::string(what) + ": " + std::to_string(n) + " blocks exceed its capacity of " +
           std::to_string(params.block_capacity));
    // Every stream first: a lying stream must not cost a volume's allocation.
    const std::vector<std::int32_t> coordinates = compressed<std::int32_t>(3 * std::size_t(n), what);
    std::vector<S> sdf = compressed<S>(std::size_t(n) * SparseTsdfVolume<S, B>::block_voxels, what);
    std::vector<S> weight = compressed<S>(std::size_t(n) * SparseTsdfVolume<S, B>::block_voxels, what);
    std::vector<Vec3i> blocks(static_cast<std::size_t>(n));
    for (std::size_t b = 0; b < blocks.size(); ++b)
      blocks[b] = Vec3i{{coordinates[3 * b], coordinates[3 * b + 1], coordinates[3 * b + 2]}};
    SparseTsdfVolume<S, B> v(params, backend);
    try {
      v.assign_from_host(blocks, sdf, weight);
    } catch (const std::invalid_argument& e) {
      fail(std::string(what) + ": " + e.what());
    }
    return v;
  }
  /// The background of a checkpoint of `version`: dense in version 1, else
  /// a kind (0 dense, 1 sparse) and the volume.
  template <class S, Backend B>
  BackgroundVolume<S, B> background(std::uint32_t version, const B& backend) {
    constexpr const char* what = "the background volume";
    const unsigned kind = version >= 2 ? u8("the background's kind") : 0;
    if (kind == 0) return BackgroundVolume<S, B>(volume<S, B>(what, backend));
    if (kind == 1) return BackgroundVolume<S, B>(sparse_volume<S, B>(what, backend));
    fail("unknown background kind " + std::to_string(kind) + " (0 dense, 1 sparse)");
  }
  template <class S, Backend B>
  std::unique_ptr<ObjectModel<S, B>> object(const B& backend) {
    const int id = i32("an object's id");
    std::string class_name = string("an object's class");
    std::vector<std::pair<std::string, double>> scores(count("an object's class scores", 12));
    for (auto& [name, score] : scores) {
      name = string("a class score");
      score = f64("a class score");
    }
    const SE3<S> T_world_object = pose<S>("an object's pose");
    const SE3<S> T_object_volume = pose<S>("an object's volume pose");
    const int existence = i32("an object's existence count");
    const int non_existence = i32("an object's non-existence count");
    if (existence < 0 || non_existence < 0 || existence + std::int64_t(non_existence) == 0)
      fail("object " + std::to_string(id) + ": existence counts " + std::to_string(existence) + "/" +
           std::to_string(non_existence) + " are not counts");
    TsdfVolume<S, B> volume = this->volume<S, B>("an object's volume", backend);
    const Vec3i d = volume.dims();
    const std::size_t n = std::size_t(volume.voxel_count());
    std::vector<float> fg = compressed<float>(n, "an object's foreground counts");
    std::vector<float> bg = compressed<float>(n, "an object's background counts");
    ForegroundCounts<S, B> counts(d, volume.voxel_size(), backend);
    counts.assign_from_host(fg, bg);
    auto o = std::make_unique<ObjectModel<S, B>>(ObjectModel<S, B>::restore(
        id, std::move(class_name), std::move(scores), T_world_object, T_object_volume, std::move(volume),
        std::move(counts), existence, non_existence));
    // The volume's pose is T_world_object T_object_volume again: finite
    // factors can still overflow in the product.
    const SE3<S>& T = o->volume().pose();
    for (int i = 0; i < 9; ++i)
      if (!std::isfinite(double(T.rotation()[i])) || (i < 3 && !std::isfinite(double(T.translation()[i]))))
        fail("object " + std::to_string(id) + ": its poses overflow");
    return o;
  }
  /// Version 4: an object's colour, if it was saved with one.
  template <class S, Backend B>
  void colour(ObjectModel<S, B>& o) {
    if (!flag("an object's colour flag")) return;
    const std::size_t n = std::size_t(o.volume().voxel_count());
    std::vector<float> values = compressed<float>(n, "an object's gray values");
    std::vector<float> weights = compressed<float>(n, "an object's colour weights");
    o.enable_colour();
    o.colour().assign_from_host(values, weights);
  }

 private:
  const unsigned char* p_;
  const unsigned char* end_;
  std::string source_;
};

}  // namespace detail::checkpoint

namespace detail::checkpoint {
template <class S>
std::string camera_text(const PinholeCamera<S>& c) {
  char text[160];
  std::snprintf(text, sizeof(text), "%dx%d fx %.9g fy %.9g cx %.9g cy %.9g", c.width, c.height, double(c.fx),
                double(c.fy), double(c.cx), double(c.cy));
  return text;
}
template <class S, Backend B>
std::string grid_text(const TsdfVolume<S, B>& v) {
  char text[160];
  std::snprintf(text, sizeof(text), "%dx%dx%d voxels of %.9g m, truncation %.9g m", v.dims()[0], v.dims()[1],
                v.dims()[2], double(v.voxel_size()), double(v.truncation()));
  return text;
}
template <class S, Backend B>
std::string grid_text(const SparseTsdfVolume<S, B>& v) {
  char text[160];
  std::snprintf(text, sizeof(text), "at most %d blocks of 8^3 voxels of %.9g m, truncation %.9g m", v.capacity(),
                double(v.voxel_size()), double(v.truncation()));
  return text;
}
/// The background's kind and grid, for messages.
template <class S, Backend B>
std::string background_text(const BackgroundVolume<S, B>& b) {
  return std::string(b.is_sparse() ? "sparse" : "dense") + " background of " +
         b.visit([](const auto& v) { return grid_text(v); });
}
}  // namespace detail::checkpoint

/// The bytes of a checkpoint of `map` made with `camera` (docs/io.md,
/// "Checkpoints").
template <class S, Backend B>
std::string checkpoint_bytes(const Map<S, B>& map, const PinholeCamera<S>& camera) {
  static_assert(sizeof(S) == 4 || sizeof(S) == 8, "checkpoints hold float or double maps");
  detail::checkpoint::Writer w;
  w.i32(camera.width);
  w.i32(camera.height);
  w.scalar(camera.fx), w.scalar(camera.fy), w.scalar(camera.cx), w.scalar(camera.cy);
  w.i32(map.frames);
  w.u8(map.started ? 1 : 0);
  w.i32(map.next_id);
  w.pose(map.T_world_camera);
  w.trajectory(map.camera_trajectory);
  w.u64(map.young.size());
  for (int id : map.young) w.i32(id);
  w.u64(map.records.size());
  for (const ObjectRecord& r : map.records) {
    w.i32(r.id);
    w.string(r.class_name);
    w.f64(r.first_timestamp);
    w.f64(r.last_timestamp);
    w.u8(r.deleted ? 1 : 0);
    w.u8(unsigned(r.reason));
    w.u8(r.person ? 1 : 0);
    w.trajectory(r.trajectory);
  }
  w.background(map.background);
  w.u64(map.objects.size());
  for (const auto& o : map.objects) w.object(*o);
  w.u64(map.lost.size());
  for (const LostObject<S, B>& l : map.lost) {
    w.i32(l.lost_at);
    w.object(*l.object);
  }
  for (const ObjectRecord& r : map.records) w.f64(r.hidden_since);  // version 3
  for (const auto& o : map.objects) w.colour(*o);                   // version 4
  for (const LostObject<S, B>& l : map.lost) w.colour(*l.object);
  for (const LostObject<S, B>& l : map.lost) w.u8(l.held_detection ? 1 : 0);  // version 5

  std::string out(checkpoint_magic, checkpoint_magic + 8);
  detail::bytes::put_u32(out, checkpoint_version);
  detail::bytes::put_u8(out, sizeof(S));
  out.append(3, '\0');
  detail::bytes::put_u64(out, w.out.size());
  out += w.out;
  detail::bytes::put_u32(out, detail::checkpoint::crc32_of(reinterpret_cast<const unsigned char*>(w.out.data()),
                                                           w.out.size()));
  return out;
}

/// Writes a checkpoint of `map` made with `camera` to `path`, through
/// "<path>.tmp" renamed over it when complete: a checkpoint on disk is
/// always a whole one. Throws std::runtime_error naming the file.
template <class S, Backend B>
void save_checkpoint(const std::string& path, const Map<S, B>& map, const PinholeCamera<S>& camera) {
  const std::string bytes = checkpoint_bytes(map, camera);
  detail::io::AtomicFile file("save_checkpoint", path);
  errno = 0;
  const bool written = std::fwrite(bytes.data(), 1, bytes.size(), file.get()) == bytes.size();
  file.commit(written ? "" : detail::io::errno_text(errno));
}

/// The checkpoint in `data`; `source` names it in errors. Throws
/// std::runtime_error for anything but a whole, intact checkpoint of
/// version <= checkpoint_version with scalar S.
template <class S, Backend B = Host>
Checkpoint<S, B> parse_checkpoint(const std::string& data, const std::string& source, B backend = B{}) {
  namespace ck = detail::checkpoint;
  const auto* p = reinterpret_cast<const unsigned char*>(data.data());
  ck::Reader header(p, data.size(), source);
  if (data.size() < 8 || std::memcmp(p, checkpoint_magic, 8) != 0)
    header.fail("not an emfusion checkpoint (no EMFCKPT magic)");
  if (data.size() < ck::header_bytes)
    header.fail("truncated: " + std::to_string(data.size()) + " bytes, shorter than the header");
  const std::uint32_t version = detail::bytes::u32(p + 8);
  if (version == 0 || version > checkpoint_version)
    header.fail("version " + std::to_string(version) + " is not supported (this build reads up to version " +
                std::to_string(checkpoint_version) + ")");
  const unsigned scalar = p[12];
  if (scalar != sizeof(S))
    header.fail("a checkpoint of " + std::string(scalar == 4 ? "float" : scalar == 8 ? "double" : "unknown") +
                " scalars (size " + std::to_string(scalar) + "), expected " + (sizeof(S) == 4 ? "float" : "double"));
  const std::uint64_t payload = detail::bytes::u64(p + 16);
  const std::size_t available = data.size() - ck::header_bytes;
  if (available < ck::crc_bytes || payload > available - ck::crc_bytes)
    header.fail("truncated: the header announces " + std::to_string(payload) + " payload bytes and a CRC, " +
                std::to_string(available) + " bytes follow");
  if (payload < available - ck::crc_bytes)
    header.fail(std::to_string(available - ck::crc_bytes - payload) + " bytes follow the checksum");
  const unsigned char* body = p + ck::header_bytes;
  const std::uint32_t stored = detail::bytes::u32(body + payload);
  if (ck::crc32_of(body, std::size_t(payload)) != stored) header.fail("checksum mismatch: the file is corrupt");

  ck::Reader r(body, std::size_t(payload), source);
  PinholeCamera<S> camera;
  camera.width = r.i32("the camera");
  camera.height = r.i32("the camera");
  camera.fx = r.finite<S>("the camera"), camera.fy = r.finite<S>("the camera");
  camera.cx = r.finite<S>("the camera"), camera.cy = r.finite<S>("the camera");
  if (camera.width < 1 || camera.height < 1) r.fail("the camera size must be positive");
  const int frames = r.i32("the frame count");
  if (frames < 0) r.fail("negative frame count");
  const bool started = r.flag("the started flag");
  const int next_id = r.i32("the next id");
  const SE3<S> T_world_camera = r.pose<S>("the camera pose");
  Trajectory camera_trajectory = r.trajectory("the camera trajectory");
  std::vector<int> young(r.count("the young objects", 4));
  for (int& id : young) id = r.i32("a young object");
  std::vector<ObjectRecord> records(r.count("the object records", 4 + 4 + 8 + 8 + 3 + 8));
  for (ObjectRecord& rec : records) {
    rec.id = r.i32("an object record");
    rec.class_name = r.string("an object record");
    rec.first_timestamp = r.f64("an object record");
    rec.last_timestamp = r.f64("an object record");
    rec.deleted = r.flag("an object record's deleted flag");
    const unsigned reason = r.u8("an object record");
    if (reason > unsigned(DeletionReason::merged))
      r.fail("object record " + std::to_string(rec.id) + ": unknown deletion reason " + std::to_string(reason));
    rec.reason = DeletionReason(reason);
    rec.person = r.flag("an object record's person flag");
    rec.trajectory = r.trajectory("an object record's trajectory");
  }
  BackgroundVolume<S, B> background = r.template background<S, B>(version, backend);
  // The smallest valid map; its background is replaced by the loaded one,
  // which may be of any size (System::restore checks it against its parameters).
  SystemParams<S> small;
  small.background_voxels = 8;
  Checkpoint<S, B> out{camera, Map<S, B>(small, backend)};
  Map<S, B>& map = out.map;
  map.background = std::move(background);
  map.frames = frames, map.started = started, map.next_id = next_id;
  map.T_world_camera = T_world_camera;
  map.camera_trajectory = std::move(camera_trajectory);
  map.young = std::move(young);
  map.records = std::move(records);
  // An object's volume and counts take at least their two header-sized
  // fields and four streams: 200 bytes is a safe lower bound per object.
  const std::size_t objects = r.count("the live objects", 200);
  for (std::size_t k = 0; k < objects; ++k) map.objects.push_back(r.template object<S, B>(backend));
  const std::size_t lost = r.count("the lost objects", 200);
  for (std::size_t k = 0; k < lost; ++k) {
    LostObject<S, B> l;
    l.lost_at = r.i32("a lost object");
    if (l.lost_at < 0 || l.lost_at > frames)
      r.fail("a lost object was lost at frame " + std::to_string(l.lost_at) + ", outside 0.." + std::to_string(frames));
    l.object = r.template object<S, B>(backend);
    map.lost.push_back(std::move(l));
  }
  // Version 3: since when each record's object is held hidden (NaN: it is not).
  if (version >= 3)
    for (ObjectRecord& rec : map.records) {
      rec.hidden_since = r.f64("an object record's hidden time");
      if (std::isinf(rec.hidden_since)) r.fail("object record " + std::to_string(rec.id) + ": infinite hidden time");
    }
  // Version 4: each live and then each lost object's colour.
  if (version >= 4) {
    for (auto& o : map.objects) r.colour(*o);
    for (LostObject<S, B>& l : map.lost) r.colour(*l.object);
  }
  // Version 5: whether each lost object held a detection.
  if (version >= 5)
    for (LostObject<S, B>& l : map.lost) l.held_detection = r.flag("a lost object's held flag");
  if (r.left() != 0)
    r.fail(std::to_string(r.left()) + " bytes follow the " +
           (version >= 5   ? "lost objects' held flags"
            : version >= 4 ? "objects' colour"
            : version >= 3 ? "records' hidden times"
                           : "last lost object"));
  // Every live and lost object has a record (Map::record_of relies on it).
  const auto has_record = [&](int id) {
    for (const ObjectRecord& rec : map.records)
      if (rec.id == id) return true;
    return false;
  };
  for (const auto& o : map.objects)
    if (!has_record(o->id())) r.fail("live object " + std::to_string(o->id()) + " has no record");
  for (const auto& l : map.lost)
    if (!has_record(l.object->id())) r.fail("lost object " + std::to_string(l.object->id()) + " has no record");
  return out;
}

/// Reads the checkpoint at `path` (parse_checkpoint); errors name the file.
template <class S, Backend B = Host>
Checkpoint<S, B> load_checkpoint(const std::string& path, B backend = B{}) {
  return parse_checkpoint<S, B>(detail::io::read_file(path, "load_checkpoint"), path, backend);
}

/// Writes a checkpoint of `system`'s state (save_checkpoint of its map and camera).
template <class S, Backend B, class L, class BN, class ON, class Solver>
void save_checkpoint(const std::string& path, const System<S, B, L, BN, ON, Solver>& system) {
  save_checkpoint(path, system.map(), system.camera());
}

/// Replaces `system`'s state with the checkpoint at `path`: the next
/// process() goes on from the saved frame as if the run had never stopped.
/// The system must have been made with the checkpoint's camera and
/// background grid (the parameters are not saved: give the same ones);
/// otherwise std::invalid_argument naming the file, the system unchanged.
template <class S, Backend B, class L, class BN, class ON, class Solver>
void restore_checkpoint(System<S, B, L, BN, ON, Solver>& system, const std::string& path) {
  Checkpoint<S, B> ck = load_checkpoint<S, B>(path, system.background().backend());
  const auto refuse = [&](const std::string& problem) {
    throw std::invalid_argument("restore_checkpoint: " + detail::io::quoted(path) + ": " + problem);
  };
  const PinholeCamera<S>& c = system.camera();
  if (ck.camera.width != c.width || ck.camera.height != c.height || ck.camera.fx != c.fx || ck.camera.fy != c.fy ||
      ck.camera.cx != c.cx || ck.camera.cy != c.cy)
    refuse("saved with camera " + detail::checkpoint::camera_text(ck.camera) + ", the system has " + detail::checkpoint::camera_text(c));
  const BackgroundVolume<S, B>& bg = system.background();
  const BackgroundVolume<S, B>& saved = ck.map.background;
  bool same = saved.is_sparse() == bg.is_sparse() && saved.voxel_size() == bg.voxel_size() &&
              saved.truncation() == bg.truncation();
  if (same && !saved.is_sparse()) {
    const Vec3i &d = saved.dense()->dims(), &e = bg.dense()->dims();
    same = d[0] == e[0] && d[1] == e[1] && d[2] == e[2];
  }
  if (same && saved.is_sparse()) same = saved.sparse()->capacity() == bg.sparse()->capacity();
  if (!same)
    refuse("saved with a " + detail::checkpoint::background_text(saved) + ", the system's parameters give a " +
           detail::checkpoint::background_text(bg));
  system.restore(std::move(ck.map));
}

}  // namespace emfusion

// Dynamic synthetic scenes with full ground truth: a static room plus rigid
// objects that move along known trajectories, seen by a moving camera with
// Kinect-like depth noise. They stand in for recorded sequences in tests,
// benchmarks and demos: every pose and every visible-instance label is known.
//
// `DynamicScene` holds a scene (shapes, per-frame poses, camera, noise model)
// and renders it; `make_dynamic_room` (a room) and `make_dynamic_corridor`
// (a corridor 15 m long) generate one from a few parameters;
// `SyntheticSequence` adapts a scene to the FrameSource concept.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "emfusion/core/backend.hpp"
#include "emfusion/core/camera.hpp"
#include "emfusion/core/error.hpp"
#include "emfusion/core/image.hpp"
#include "emfusion/core/parallel.hpp"
#include "emfusion/core/se3.hpp"
#include "emfusion/core/timed_pose.hpp"
#include "emfusion/sim/noise.hpp"
#include "emfusion/sim/primitives.hpp"

namespace emfusion::sim {

/// A rigid object of a dynamic scene.
template <class S>
struct MovingObject {
  std::string name;        ///< unique, "<class>_<label>" by convention (e.g. "car_1")
  std::string class_name;  ///< COCO name, spaces written as '_' (e.g. "teddy_bear")
  /// The object's shapes in the OBJECT frame: a shape's T_shape_world field
  /// holds T_shape_object here (build them with make_box etc. and object-frame
  /// poses). Planes are not allowed: an object must be bounded.
  std::vector<Shape<S>> shapes;
  std::vector<SE3<double>> T_world_object;  ///< one pose per frame
};

namespace detail {

/// Radius of a sphere about the object origin that contains the shape:
/// exact for boxes and spheres; for cylinders the largest of 64 rim points
/// per cap, plus the most a chord can fall short of the arc.
template <class S>
double bounding_radius(const Shape<S>& shape_in_object) {
  const SE3<double> T_object_shape = shape_in_object.T_shape_world.template cast<double>().inverse();
  const Vec3<double> size = shape_in_object.size.template cast<double>();
  double r = 0;
  switch (shape_in_object.type) {
    case ShapeType::box:
      for (int c = 0; c < 8; ++c)
        r = std::fmax(r, norm(T_object_shape * vec3(c & 1 ? size.x() : -size.x(), c & 2 ? size.y() : -size.y(),
                                                    c & 4 ? size.z() : -size.z())));
      return r;
    case ShapeType::sphere:
      return norm(T_object_shape.translation()) + size.x();
    case ShapeType::cylinder:
      for (int i = 0; i < 64; ++i) {
        const double a = 2 * 3.14159265358979323846 * i / 64;
        for (double z : {-size.y(), size.y()})
          r = std::fmax(r, norm(T_object_shape * vec3(size.x() * std::cos(a), size.x() * std::sin(a), z)));
      }
      return r + size.x() * (1 - std::cos(3.14159265358979323846 / 64));
    case ShapeType::plane:
      break;
  }
  return 1e30;
}

/// Narrows [t_in, t_out] to where |o + t d| <= h along one axis.
template <class S>
EMF_HD void clip_to_slab(S o, S d, S h, S& t_in, S& t_out) {
  if (std::fabs(d) < S(1e-12)) {
    if (std::fabs(o) > h) t_out = S(-1);
    return;
  }
  S t0 = (-h - o) / d, t1 = (h - o) / d;
  if (t0 > t1) {
    const S tmp = t0;
    t0 = t1, t1 = tmp;
  }
  t_in = t0 > t_in ? t0 : t_in;
  t_out = t1 < t_out ? t1 : t_out;
}

/// Distance along the unit ray o + t d (shape frame) to where it enters the
/// shape, or -1 if it misses. Every primitive is convex, so the ray enters at
/// the largest entry parameter of the slabs (or round surface) that bound
/// it; rays that start inside a shape do not see it.
template <class S>
EMF_HD S ray_entry(const Shape<S>& shape, const Vec3<S>& o, const Vec3<S>& d) {
  S t_in = S(0), t_out = S(1e30);
  switch (shape.type) {
    case ShapeType::plane:
      if (o.z() <= S(0) || d.z() >= S(0)) return S(-1);
      return -o.z() / d.z();
    case ShapeType::sphere: {
      const S b = dot(o, d), c = dot(o, o) - shape.size.x() * shape.size.x();
      if (c <= S(0)) return S(-1);
      const S disc = b * b - c;
      if (disc < S(0) || b > S(0)) return S(-1);
      // c / (-b + sqrt) == -b - sqrt, without the cancellation at grazing rays.
      return c / (-b + std::sqrt(disc));
    }
    case ShapeType::box:
      clip_to_slab(o.x(), d.x(), shape.size.x(), t_in, t_out);
      clip_to_slab(o.y(), d.y(), shape.size.y(), t_in, t_out);
      clip_to_slab(o.z(), d.z(), shape.size.z(), t_in, t_out);
      break;
    case ShapeType::cylinder: {
      const S r = shape.size.x();
      const S a = d.x() * d.x() + d.y() * d.y();
      const S b = o.x() * d.x() + o.y() * d.y();
      const S c = o.x() * o.x() + o.y() * o.y() - r * r;
      if (a < S(1e-12)) {
        if (c > S(0)) return S(-1);
      } else {
        const S disc = b * b - a * c;
        if (disc < S(0)) return S(-1);
        const S q = std::sqrt(disc);
        const S t0 = (-b - q) / a, t1 = (-b + q) / a;
        t_in = t0 > t_in ? t0 : t_in;
        t_out = t1 < t_out ? t1 : t_out;
      }
      clip_to_slab(o.z(), d.z(), shape.size.y(), t_in, t_out);
      break;
    }
  }
  return (t_out >= t_in && t_in > S(0)) ? t_in : S(-1);
}

/// One pixel of an exact ray cast: depth of the nearest surface (0 if none
/// within max_depth) and the instance label there (0 static or none, k + 1
/// object k).
template <class S>
struct RaycastPixel {
  Scene<S> scene;
  int label_of_shape[Scene<S>::capacity];
  PinholeCamera<S> camera;
  SE3<S> T_world_camera;
  S max_depth;
  ImageView<S> depth;
  ImageView<int> labels;

  EMF_HD void operator()(int i) const {
    const int u = i % camera.width, v = i / camera.width;
    const Vec3<S> ray_cam = camera.ray(S(u), S(v));
    const Vec3<S> d = T_world_camera.rotate(normalized(ray_cam));
    const Vec3<S> o = T_world_camera.translation();
    S best = S(1e30);
    int label = 0;
    for (int k = 0; k < scene.count; ++k) {
      const Shape<S>& shape = scene.shapes[k];
      const S t = ray_entry(shape, shape.T_shape_world * o, shape.T_shape_world.rotate(d));
      if (t > S(0) && t < best) best = t, label = label_of_shape[k];
    }
    // Depth is the z coordinate: t times the unit ray's z = 1 / |ray_cam|.
    const S z = best / norm(ray_cam);
    const bool hit = best < S(1e30) && z <= max_depth;
    depth[i] = hit ? z : S(0);
    if (!labels.empty()) labels[i] = hit ? label : 0;
  }
};

}  // namespace detail

/// A static set of shapes plus K moving rigid objects, a camera trajectory and
/// a depth noise model; frame f has timestamp f / fps.
template <class S>
class DynamicScene {
 public:
  using Scalar = S;

  /// Checks that every trajectory has one pose per frame and that all shapes
  /// fit into one Scene (Scene<S>::capacity). `seed` drives the depth noise.
  DynamicScene(const PinholeCamera<S>& camera, std::vector<Shape<S>> static_shapes,
               std::vector<MovingObject<S>> objects, std::vector<SE3<double>> T_world_camera,
               const DepthNoise& noise = {}, std::uint64_t seed = 1, double fps = 30)
      : camera_(camera),
        static_(std::move(static_shapes)),
        objects_(std::move(objects)),
        camera_poses_(std::move(T_world_camera)),
        noise_(noise),
        seed_(seed),
        fps_(fps) {
    const char* where = "DynamicScene";
    camera_.validate(where);
    noise_.validate(where);
    emfusion::detail::require(fps_ > 0 && std::isfinite(fps_), where, "fps must be positive");
    emfusion::detail::require(!camera_poses_.empty(), where, "the camera trajectory is empty (need >= 1 frame)");
    std::size_t shapes = static_.size();
    for (const MovingObject<S>& o : objects_) {
      emfusion::detail::require(!o.shapes.empty(), where, "object '" + o.name + "' has no shapes");
      emfusion::detail::require(o.T_world_object.size() == camera_poses_.size(), where,
                                "object '" + o.name + "' has " + std::to_string(o.T_world_object.size()) +
                                    " poses but the camera has " + std::to_string(camera_poses_.size()));
      double r = 0;
      for (const Shape<S>& s : o.shapes) {
        emfusion::detail::require(s.type != ShapeType::plane, where,
                                  "object '" + o.name + "' has a plane; objects must be bounded");
        r = std::fmax(r, detail::bounding_radius(s));
      }
      radius_.push_back(r);
      shapes += o.shapes.size();
    }
    emfusion::detail::require(shapes <= std::size_t(Scene<S>::capacity), where,
                              std::to_string(shapes) + " shapes do not fit into a Scene (capacity " +
                                  std::to_string(Scene<S>::capacity) + ")");
    shape_object_.assign(static_.size(), -1);
    for (int k = 0; k < object_count(); ++k)
      for (std::size_t j = 0; j < objects_[std::size_t(k)].shapes.size(); ++j) shape_object_.push_back(k);
  }

  int frame_count() const { return int(camera_poses_.size()); }
  double fps() const { return fps_; }
  double timestamp(int frame) const { return double(frame) / fps_; }
  const PinholeCamera<S>& camera() const { return camera_; }
  const DepthNoise& noise() const { return noise_; }
  std::uint64_t seed() const { return seed_; }

  /// T_world_camera at a frame.
  SE3<S> camera_pose(int frame) const {
    check_frame(frame, "DynamicScene::camera_pose");
    return camera_poses_[std::size_t(frame)].template cast<S>();
  }

  int object_count() const { return int(objects_.size()); }
  const std::string& object_name(int k) const { return object(k, "DynamicScene::object_name").name; }
  const std::string& object_class(int k) const { return object(k, "DynamicScene::object_class").class_name; }
  /// The object's shapes in its own frame (see MovingObject::shapes).
  const std::vector<Shape<S>>& object_shapes(int k) const { return object(k, "DynamicScene::object_shapes").shapes; }
  /// Radius of a sphere about the object's origin that contains it.
  double object_radius(int k) const {
    object(k, "DynamicScene::object_radius");
    return radius_[std::size_t(k)];
  }
  /// T_world_object of object k at a frame.
  SE3<S> object_pose(int k, int frame) const {
    check_frame(frame, "DynamicScene::object_pose");
    return object(k, "DynamicScene::object_pose").T_world_object[std::size_t(frame)].template cast<S>();
  }

  /// Ground truth in TUM form (double poses, one per frame).
  Trajectory camera_trajectory() const { return trajectory(camera_poses_); }
  Trajectory object_trajectory(int k) const {
    return trajectory(object(k, "DynamicScene::object_trajectory").T_world_object);
  }

  /// All shapes posed in the world at a frame: the static ones first, then
  /// each object's in order. The layout is the same in every frame;
  /// object_of_shape() tells which object a shape index belongs to.
  Scene<S> scene_at(int frame) const {
    check_frame(frame, "DynamicScene::scene_at");
    Scene<S> scene;
    for (const Shape<S>& s : static_) scene.add(s);
    for (const MovingObject<S>& o : objects_) {
      const SE3<S> T_object_world = o.T_world_object[std::size_t(frame)].inverse().template cast<S>();
      for (Shape<S> s : o.shapes) {
        s.T_shape_world = s.T_shape_world * T_object_world;
        scene.add(s);
      }
    }
    return scene;
  }
  /// -1 for a static shape of scene_at(), else the index of its object.
  int object_of_shape(int shape) const {
    emfusion::detail::require(
        shape >= 0 && shape < int(shape_object_.size()), "DynamicScene::object_of_shape",
        "shape " + std::to_string(shape) + " is not in 0.." + std::to_string(int(shape_object_.size()) - 1));
    return shape_object_[std::size_t(shape)];
  }

  /// Renders a frame: depth in metres (0 = no measurement), with the sensor
  /// noise model when `noisy`, and optionally the exact visible-instance
  /// labels (0 static or nothing, k + 1 object k; never noisy). Images are
  /// (re)allocated to the camera size on `backend`. The backend comes from
  /// `depth` alone, so `labels` may be a plain nullptr.
  template <Backend B>
  void render(int frame, Image<S, B>& depth, std::type_identity_t<Image<int, B>>* labels = nullptr, bool noisy = true,
              const B& backend = B{}) const {
    check_frame(frame, "DynamicScene::render");
    const int w = camera_.width, h = camera_.height;
    detail::RaycastPixel<S> cast{scene_at(frame), {}, camera_, camera_pose(frame), S(1e3), {}, {}};
    for (int i = 0; i < Scene<S>::capacity; ++i)
      cast.label_of_shape[i] = i < int(shape_object_.size()) ? shape_object_[std::size_t(i)] + 1 : 0;
    if (labels) {
      if (!labels->same_size(w, h)) *labels = Image<int, B>(w, h, 0, backend);
      cast.labels = labels->view();
    }
    if (!depth.same_size(w, h)) depth = Image<S, B>(w, h, S(0), backend);
    if (noisy) {
      Image<S, B> clean(w, h, S(0), depth.backend());
      cast.depth = clean.view();
      for_each_index(depth.backend(), w * h, cast);
      add_depth_noise(clean, depth, noise_, seed_, frame);
    } else {
      cast.depth = depth.view();
      for_each_index(depth.backend(), w * h, cast);
    }
  }

 private:
  void check_frame(int frame, const char* where) const {
    emfusion::detail::require(frame >= 0 && frame < frame_count(), where,
                              "frame " + std::to_string(frame) + " is not in 0.." + std::to_string(frame_count() - 1));
  }
  const MovingObject<S>& object(int k, const char* where) const {
    emfusion::detail::require(k >= 0 && k < object_count(), where,
                              "object " + std::to_string(k) + " is not in 0.." + std::to_string(object_count() - 1));
    return objects_[std::size_t(k)];
  }
  Trajectory trajectory(const std::vector<SE3<double>>& poses) const {
    Trajectory t;
    t.reserve(poses.size());
    for (std::size_t f = 0; f < poses.size(); ++f) t.push_back(TimedPose{timestamp(int(f)), poses[f]});
    return t;
  }

  PinholeCamera<S> camera_;
  std::vector<Shape<S>> static_;
  std::vector<MovingObject<S>> objects_;
  std::vector<SE3<double>> camera_poses_;
  DepthNoise noise_;
  std::uint64_t seed_;
  double fps_;
  std::vector<double> radius_;
  std::vector<int> shape_object_;
};

/// The camera's path through the room (make_dynamic_room).
enum class CameraPath {
  /// A slow hand-held sweep in front of the table (peak about 0.23 m/s and
  /// 4 deg/s).
  hand_held,
  /// The same sweep with fast segments: every few seconds (placement from the
  /// seed) a stretch of 1.6-2.4 s in which the sweep is played up to twice as
  /// fast while the camera swings sideways and turns away and back, eased in
  /// and out (sin^2 profiles, zero acceleration jump at the ends), peaking at
  /// 0.70-0.85 m/s and 35-42 deg/s: the fastest parts of a real hand-held
  /// recording. Between the segments it is the hand_held path, time-shifted.
  hand_held_fast,
};

/// The static world of a dynamic scene.
enum class SceneLayout {
  /// A 5 x 4 x 3 m room with a table and furniture; the camera sweeps in
  /// front of the table (make_dynamic_room).
  room,
  /// A corridor 15 m long with three tables and furniture along one wall;
  /// the camera walks 11 m along it looking at the wall, and objects on the
  /// tables move while it passes (make_dynamic_corridor): a world larger
  /// than a 5 m volume holds.
  corridor,
};

/// The most moving objects make_dynamic_room places (one of each kind).
constexpr int max_room_objects = 16;

/// What make_dynamic_room and make_dynamic_corridor build (make_dynamic_scene picks by `layout`).
struct DynamicSceneParams {
  SceneLayout layout = SceneLayout::room;
  int frames = 300;
  int width = 640, height = 480;  ///< intrinsics scale with width: f = 525 * width / 640
  int moving_objects = 3;         ///< 0..16 in the room, 0..6 in the corridor (0: a static scene)
  std::uint64_t seed = 1;         ///< object placement, motions, fast segments and depth noise
  bool moving_camera = true;      ///< false: the camera stays at its first pose
  CameraPath camera_path = CameraPath::hand_held;  ///< the room's camera (the corridor has its own walk)
  DepthNoise noise{};
};

namespace detail {

/// Checks what every generated scene takes from `params` (objects in
/// 0..max_objects, frames, image size, noise) and returns its camera:
/// f = 525 * width / 640, the principal point at the image centre.
inline PinholeCamera<double> scene_camera(const DynamicSceneParams& params, int max_objects, const char* where) {
  emfusion::detail::require(params.moving_objects >= 0 && params.moving_objects <= max_objects, where,
                            "moving_objects must be in 0.." + std::to_string(max_objects) + ", got " +
                                std::to_string(params.moving_objects));
  emfusion::detail::require(params.frames >= 1, where, "frames must be >= 1, got " + std::to_string(params.frames));
  emfusion::detail::require(
      params.width >= 16 && params.height >= 16, where,
      "image size must be at least 16x16, got " + std::to_string(params.width) + "x" + std::to_string(params.height));
  params.noise.validate(where);
  const double f = 525.0 * params.width / 640.0;
  return {f, f, (params.width - 1) / 2.0, (params.height - 1) / 2.0, params.width, params.height};
}

}  // namespace detail

namespace detail::room {

constexpr double fps = 30;
constexpr double pi = 3.14159265358979323846;
constexpr double max_speed = 0.35;               // m/s, peak of an eased segment
constexpr double max_turn_rate = 50 * pi / 180;  // rad/s, peak
constexpr double table_top = 0.5;                // m, height of the table surface
constexpr double clearance = 0.03;               // m, between bounding spheres

/// An object's template: what it looks like and where it may move.
struct Kind {
  const char* class_name;
  double half_height;  // object-frame z extent is [-half_height, half_height]
  bool on_floor;       // else on the table
};

// Classes in the order objects are created; the first three match the README
// of room_dyn_300 (car, cup, book). Kinds 8..15 only appear in rooms of more
// than 8 objects: a bowl, a handbag, a suitcase and a cat, and smaller
// variants of the cup, book, car and bottle; they alternate between the
// table and the floor.
inline const Kind kinds[max_room_objects] = {
    {"car", 0.09, false},        {"cup", 0.11, false},         {"book", 0.05, false},    {"backpack", 0.16, true},
    {"teddy_bear", 0.16, false}, {"potted_plant", 0.17, true}, {"laptop", 0.112, false}, {"bottle", 0.09, true},
    {"bowl", 0.06, false},       {"handbag", 0.11, true},      {"cup", 0.095, false},    {"suitcase", 0.15, true},
    {"book", 0.045, false},      {"cat", 0.1, true},          {"car", 0.075, false},    {"bottle", 0.075, true},
};

/// Object-frame shapes of kind k: two primitives each, placed off-centre so
/// that no rotation maps the object onto itself (rotations are observable).
template <class S>
std::vector<Shape<S>> kind_shapes(int kind) {
  auto at = [](double x, double y, double z) { return SE3<S>::translation(vec3(S(x), S(y), S(z))); };
  auto half = [](double x, double y, double z) { return vec3(S(x), S(y), S(z)); };
  const SE3<S> along_x(so3_exp(vec3(S(0), S(pi / 2), S(0))), Vec3<S>::zero());
  auto along_x_at = [&](double x) { return SE3<S>(along_x.rotation(), vec3(S(x), S(0), S(0))); };
  switch (kind) {
    case 0:  // toy car: body and a cabin towards the back
      return {make_box(at(0, 0, -0.035), half(0.17, 0.09, 0.055)),
              make_box(at(-0.05, 0, 0.045), half(0.08, 0.08, 0.045))};
    case 1:  // mug: cylinder and a handle on one side
      return {make_cylinder(at(-0.03, 0, 0), S(0.1), S(0.11)), make_box(at(0.1, 0, 0), half(0.035, 0.018, 0.065))};
    case 2:  // two stacked books, the top one shifted
      return {make_box(at(0, 0, -0.02), half(0.12, 0.16, 0.03)),
              make_box(at(0.03, 0.05, 0.025), half(0.09, 0.11, 0.025))};
    case 3:  // backpack: main bag and a front pocket low down
      return {make_box(at(0, 0.02, 0), half(0.13, 0.08, 0.16)), make_box(at(0, -0.09, -0.06), half(0.09, 0.04, 0.08))};
    case 4:  // teddy bear: body and a head set forward
      return {make_sphere(vec3(S(0), S(0), S(-0.04)), S(0.12)), make_sphere(vec3(S(0.05), S(0), S(0.08)), S(0.08))};
    case 5:  // potted plant: pot and foliage leaning to one side
      return {make_cylinder(at(0, 0, -0.09), S(0.09), S(0.08)), make_sphere(vec3(S(0.04), S(0.02), S(0.05)), S(0.12))};
    case 6:  // open laptop: base and the screen at its back edge
      return {make_box(at(0, 0, -0.1), half(0.16, 0.12, 0.012)), make_box(at(0, 0.11, 0), half(0.16, 0.01, 0.11))};
    case 7:  // bottle lying on its side: body and neck along x
      return {make_cylinder(along_x_at(-0.06), S(0.09), S(0.1)), make_cylinder(along_x_at(0.1), S(0.035), S(0.06))};
    case 8:  // bowl with a fruit in it, off the bowl's axis
      return {make_cylinder(at(0, 0, -0.025), S(0.12), S(0.035)), make_sphere(vec3(S(0.04), S(0.02), S(0)), S(0.06))};
    case 9:  // handbag: bag and a handle towards one end
      return {make_box(at(0, 0, -0.03), half(0.12, 0.05, 0.08)), make_box(at(0.035, 0, 0.08), half(0.045, 0.01, 0.03))};
    case 10:  // smaller mug
      return {make_cylinder(at(-0.025, 0, 0), S(0.085), S(0.095)),
              make_box(at(0.085, 0, 0), half(0.03, 0.016, 0.055))};
    case 11:  // upright suitcase: case and a handle off-centre on top
      return {make_box(at(0, 0, -0.02), half(0.11, 0.06, 0.13)), make_box(at(0.045, 0, 0.13), half(0.035, 0.01, 0.02))};
    case 12:  // two smaller stacked books, the top one shifted the other way
      return {make_box(at(0, 0, -0.02), half(0.1, 0.13, 0.025)),
              make_box(at(-0.02, -0.03, 0.025), half(0.08, 0.1, 0.02))};
    case 13:  // cat lying down: body and a head at one end
      return {make_box(at(-0.03, 0, -0.04), half(0.11, 0.06, 0.06)), make_sphere(vec3(S(0.1), S(0), S(0.04)), S(0.06))};
    case 14:  // smaller toy car
      return {make_box(at(0, 0, -0.03), half(0.14, 0.075, 0.045)),
              make_box(at(-0.04, 0, 0.035), half(0.065, 0.065, 0.04))};
    default:  // smaller bottle lying on its side
      return {make_cylinder(along_x_at(-0.05), S(0.075), S(0.085)),
              make_cylinder(along_x_at(0.085), S(0.03), S(0.05))};
  }
}

/// The static room: 5 x 4 x 3 m (x in [-2.5, 2.5], y in [-2, 2], z up), a
/// table whose top spans x in [-1.1, 1.1], y in [0.25, 1.35] at z = 0.5,
/// and furniture along the walls that gives the camera tracker structure in
/// every direction.
template <class S>
std::vector<Shape<S>> static_shapes() {
  auto v = [](double x, double y, double z) { return vec3(S(x), S(y), S(z)); };
  auto plane = [&](Vec3<S> on, Vec3<S> inside, Vec3<S> up) { return make_plane(look_at(on, inside, up)); };
  auto box = [&](double x, double y, double z, double hx, double hy, double hz, double yaw = 0) {
    return make_box(SE3<S>(so3_exp(v(0, 0, yaw)), v(x, y, z)), v(hx, hy, hz));
  };
  const Vec3<S> up = v(0, 0, 1);
  return {
      make_plane(SE3<S>::identity()),             // floor, z = 0
      plane(v(0, 0, 3), v(0, 0, 0), v(1, 0, 0)),  // ceiling
      plane(v(-2.5, 0, 1.5), v(0, 0, 1.5), up),   // walls
      plane(v(2.5, 0, 1.5), v(0, 0, 1.5), up),
      plane(v(0, 2, 1.5), v(0, 0, 1.5), up),
      plane(v(0, -2, 1.5), v(0, 0, 1.5), up),
      box(0, 0.8, table_top - 0.02, 1.1, 0.55, 0.02),  // table top
      box(-1.05, 0.8, 0.23, 0.03, 0.5, 0.23),          // table sides
      box(1.05, 0.8, 0.23, 0.03, 0.5, 0.23),
      box(-1.3, 1.8, 0.8, 0.5, 0.18, 0.8),                                       // shelf
      box(1.4, 1.85, 0.5, 0.6, 0.15, 0.5),                                       // cabinet
      box(1.65, 0.7, 0.2, 0.25, 0.25, 0.2, 0.3),                                 // crate
      make_cylinder(SE3<S>::translation(v(-1.7, 0.3, 0.25)), S(0.18), S(0.25)),  // bin
  };
}

/// Hand-held camera: a slow sideways sweep in front of the table (peak speed
/// about 0.22 m/s), looking at a point that drifts less than the eye, so the
/// view both translates and turns.
inline Vec3<double> camera_eye_at(double t) {
  const double w = 2 * pi;
  return vec3(0.45 * std::sin(w * t / 14), -1.35 + 0.15 * std::sin(w * t / 9), 1.75 + 0.08 * std::sin(w * t / 11 + 1));
}
inline Vec3<double> camera_target_at(double t) {
  const double w = 2 * pi;
  return vec3(0.2 * std::sin(w * t / 14 + 0.5), 0.5 + 0.1 * std::sin(w * t / 10), 0.3);
}
inline SE3<double> camera_pose_at(double t) {
  return look_at(camera_eye_at(t), camera_target_at(t), vec3(0.0, 0.0, 1.0));
}

/// One fast segment of CameraPath::hand_held_fast: during [t0, t0 + duration]
/// the sweep's clock runs at 1 + (warp - 1) b(tau), the eye is shifted by
/// shift b(tau) along x and the view turned by turn b(tau) about `axis`
/// (through the eye), with b = sin^2(pi tau), tau in [0, 1]: every offset
/// starts and ends at rest, and the path is back on the sweep after it.
struct FastSegment {
  double t0 = 0, duration = 0;
  double warp = 1;   // clock rate at the peak
  double shift = 0;  // m along world x, signed
  double turn = 0;   // rad
  Vec3<double> axis = vec3(0.0, 0.0, 1.0);
};

/// The fast hand-held path: the sweep plus its fast segments.
struct FastPath {
  std::vector<FastSegment> segments;  // in time order, disjoint

  /// The sweep's clock at time t: t plus what the segments before t (and
  /// the one t is in) ran ahead.
  double clock(double t) const {
    double s = t;
    for (const FastSegment& g : segments) {
      if (t <= g.t0) break;
      const double tau = std::fmin(1.0, (t - g.t0) / g.duration);
      // Integral of sin^2(pi tau) over [0, tau], times the duration.
      s += (g.warp - 1) * g.duration * (tau / 2 - std::sin(2 * pi * tau) / (4 * pi));
    }
    return s;
  }
  SE3<double> pose(double t) const {
    const double s = clock(t);
    Vec3<double> eye = camera_eye_at(s);
    Mat3<double> turn = Mat3<double>::identity();
    for (const FastSegment& g : segments)
      if (t > g.t0 && t < g.t0 + g.duration) {
        const double b = std::sin(pi * (t - g.t0) / g.duration);
        eye = eye + vec3(g.shift * b * b, 0.0, 0.0);
        turn = so3_exp(g.turn * b * b * g.axis);
      }
    const SE3<double> base = look_at(eye, camera_target_at(s), vec3(0.0, 0.0, 1.0));
    return SE3<double>(turn * base.rotation(), eye);
  }
};

/// Peak linear (m/s) and angular (rad/s) speed of `path` over [t0, t1],
/// from differences at 240 Hz.
inline std::pair<double, double> peak_speeds(const FastPath& path, double t0, double t1) {
  const double dt = 1.0 / 240;
  double v = 0, w = 0;
  SE3<double> previous = path.pose(t0);
  for (double t = t0 + dt; t <= t1 + 1e-9; t += dt) {
    const SE3<double> next = path.pose(t);
    v = std::fmax(v, norm(next.translation() - previous.translation()) / dt);
    w = std::fmax(w, norm(so3_log((previous.rotation().transpose() * next.rotation()))) / dt);
    previous = next;
  }
  return {v, w};
}

/// The fast segments of a sequence of `duration` seconds, from the seed:
/// starts 2.5-5 s after the previous segment's end (the first 1.5-3 s in),
/// lengths 1.6-2.4 s, the clock up to twice as fast, and the sideways swing
/// and the turn sized (bisection on the measured peaks) so that the peaks
/// reach targets drawn from 0.70-0.85 m/s and 35-42 deg/s. The swing goes the
/// way the sweep moves at the segment's middle, the turn about an axis
/// between the world's vertical and the camera's x axis (a pan with some
/// tilt), either way.
inline FastPath plan_fast_path(std::uint64_t seed, double duration) {
  FastPath path;
  HashRng rng(seed, 3000);
  double t0 = rng.uniform(1.5, 3.0);
  for (;;) {
    FastSegment g;
    g.t0 = t0;
    g.duration = rng.uniform(1.6, 2.4);
    g.warp = 2;
    const double v_target = rng.uniform(0.70, 0.85), w_target = rng.uniform(35, 42) * pi / 180;
    const double tilt = rng.uniform(-0.5, 0.5);
    const bool turn_left = rng.bernoulli(0.5);
    if (g.t0 + g.duration > duration) break;
    t0 = g.t0 + g.duration + rng.uniform(2.5, 5.0);
    FastPath trial = path;
    trial.segments.push_back(g);
    const double mid = g.t0 + g.duration / 2;
    const double s_mid = trial.clock(mid);
    const double sign = camera_eye_at(s_mid + 1e-3).x() >= camera_eye_at(s_mid - 1e-3).x() ? 1 : -1;
    const Vec3<double> right = camera_pose_at(s_mid).rotation() * vec3(1.0, 0.0, 0.0);
    g.axis = normalized(std::cos(tilt) * vec3(0.0, 0.0, 1.0) + std::sin(tilt) * right);
    // Solve peak(x) = target for x in [0, hi] by bisection; peak(0) at or
    // over the target leaves x = 0.
    const auto solve = [&](double hi, auto&& peak, double target) {
      double lo = 0;
      if (peak(lo) >= target) return 0.0;
      if (peak(hi) <= target) return hi;
      for (int i = 0; i < 30; ++i) {
        const double x = (lo + hi) / 2;
        (peak(x) < target ? lo : hi) = x;
      }
      return (lo + hi) / 2;
    };
    const double end = g.t0 + g.duration;
    g.shift = sign * solve(
                         1.0,
                         [&](double shift) {
                           trial.segments.back().shift = sign * shift;
                           return peak_speeds(trial, g.t0, end).first;
                         },
                         v_target);
    trial.segments.back().shift = g.shift;
    trial.segments.back().axis = g.axis;
    const double turn_sign = turn_left ? 1 : -1;
    g.turn = turn_sign * solve(
                             1.2,
                             [&](double turn) {
                               trial.segments.back().turn = turn_sign * turn;
                               return peak_speeds(trial, g.t0, end).second;
                             },
                             w_target);
    path.segments.push_back(g);
  }
  return path;
}

/// One eased motion of an object between two rest poses on its support:
/// translation and turn follow a minimum-jerk profile; on the way the object
/// is lifted and tilted (sin^2 bump, zero velocity at both ends), as a hand
/// would carry it.
struct Motion {
  int f0 = 0, f1 = 0;  // moves during frames [f0, f1], rests at the end pose after
  double x0 = 0, y0 = 0, yaw0 = 0, x1 = 0, y1 = 0, yaw1 = 0;
  double lift = 0, tilt = 0, tilt_direction = 0;
};

struct ObjectPlan {
  double z_rest = 0, radius = 0;
  double x = 0, y = 0, yaw = 0;                   // initial rest pose
  double x_lo = 0, x_hi = 0, y_lo = 0, y_hi = 0;  // where the centre may go
  std::vector<Motion> motions;

  struct State {
    double x, y, z, yaw, tilt, tilt_direction;
  };
  State state(int f) const {
    State s{x, y, z_rest, yaw, 0, 0};
    for (const Motion& m : motions) {
      if (f < m.f0) break;
      if (f >= m.f1) {
        s = State{m.x1, m.y1, z_rest, m.yaw1, 0, 0};
        continue;
      }
      const double tau = double(f - m.f0) / double(m.f1 - m.f0);
      const double ease = tau * tau * tau * (10 - 15 * tau + 6 * tau * tau);
      const double b = std::sin(pi * tau), bump = b * b;
      s = State{m.x0 + (m.x1 - m.x0) * ease,
                m.y0 + (m.y1 - m.y0) * ease,
                z_rest + m.lift * bump,
                m.yaw0 + (m.yaw1 - m.yaw0) * ease,
                m.tilt * bump,
                m.tilt_direction};
    }
    return s;
  }
  Vec3<double> centre(int f) const {
    const State s = state(f);
    return vec3(s.x, s.y, s.z);
  }
  SE3<double> pose(int f) const {
    const State s = state(f);
    const Vec3<double> axis = vec3(std::cos(s.tilt_direction), std::sin(s.tilt_direction), 0.0);
    const Mat3<double> R = so3_exp(s.tilt * axis) * so3_exp(vec3(0.0, 0.0, s.yaw));
    return SE3<double>(R, vec3(s.x, s.y, s.z));
  }
};

/// True if the object centre projects well inside the image (8% margin) in
/// front of the camera.
inline bool in_view(const PinholeCamera<double>& camera, const SE3<double>& T_camera_world, const Vec3<double>& p) {
  const Vec3<double> q = T_camera_world * p;
  if (q.z() < 0.5) return false;
  const Vec2<double> uv = camera.project(q);
  const double mu = 0.08 * camera.width, mv = 0.08 * camera.height;
  return uv.x() >= mu && uv.x() <= camera.width - 1 - mu && uv.y() >= mv && uv.y() <= camera.height - 1 - mv;
}

/// Plans all objects' paths. Segments are planned in order of their start
/// frame; each new segment (and the rest after it, to the end of the
/// sequence) is checked against what is known of the others: their planned
/// segments and then rest. Whichever of two objects moves later thus checked
/// the pair, so no two bounding spheres ever overlap; a segment without a
/// valid candidate becomes a longer rest, which is always valid.
inline std::vector<ObjectPlan> plan_objects(int count, int frames, std::uint64_t seed,
                                            const PinholeCamera<double>& camera,
                                            const std::vector<SE3<double>>& T_camera_world,
                                            const std::vector<double>& radius) {
  std::vector<ObjectPlan> plans(static_cast<std::size_t>(count));
  // Centre of every planned object at every frame, as known so far.
  std::vector<std::vector<Vec3<double>>> track(static_cast<std::size_t>(count));
  auto update_track = [&](int k, int from) {
    auto& t = track[std::size_t(k)];
    t.resize(std::size_t(frames));
    for (int f = from; f < frames; ++f) t[std::size_t(f)] = plans[std::size_t(k)].centre(f);
  };
  // Is `candidate` (object k) in view, clear of objects 0..others-1 and not
  // hidden behind them (nor hiding them) from `from` on? Occlusion counts
  // when the projected bounding circles overlap by more than a quarter of
  // their radii: the bounding spheres are larger than the objects, so a
  // little overlap rarely hides anything.
  auto fits = [&](int k, int others, int from, const ObjectPlan& candidate) {
    for (int f = from; f < frames; ++f) {
      const SE3<double>& T = T_camera_world[std::size_t(f)];
      const Vec3<double> p = candidate.centre(f);
      if (!in_view(camera, T, p)) return false;
      const Vec3<double> pc = T * p;
      for (int j = 0; j < others; ++j) {
        if (j == k) continue;
        const Vec3<double>& q = track[std::size_t(j)][std::size_t(f)];
        const double rj = plans[std::size_t(j)].radius;
        if (norm(p - q) < candidate.radius + rj + clearance) return false;
        const Vec3<double> qc = T * q;
        if (qc.z() <= 0) continue;
        const double overlap = camera.fx * (candidate.radius / pc.z() + rj / qc.z());
        if (norm(camera.project(pc) - camera.project(qc)) < 0.75 * overlap) return false;
      }
    }
    return true;
  };

  // Rooms of more than 8 objects: drawn anywhere on their support, the first
  // objects leave no room for sixteen, so each object starts at a slot
  // (jittered by 2 cm). Each support has two rows of slots, as far apart in
  // depth as the object allows; the far row's sit between the lines of
  // sight through the near row's, so that the camera's sweep rarely lines
  // two up. Per support, objects take the far row's slots first, largest
  // first (the near row's are closer together), each row's in an order from
  // the seed; an object that does not fit at its slot tries the free ones,
  // then anywhere. Floor objects move on the floor up to under the table's
  // front edge (they are lower than the table top).
  const bool crowded = count > 8;
  std::vector<Vec2<double>> slots[2];  // [0] table, [1] floor, in the order objects take them
  std::vector<int> slot_of(static_cast<std::size_t>(count), -1);
  if (crowded) {
    HashRng order(seed, 999);
    const auto row = [&](std::vector<Vec2<double>>& to, double y, std::vector<double> xs) {
      for (int i = int(xs.size()) - 1; i > 0; --i) std::swap(xs[std::size_t(i)], xs[std::size_t(order.integer(0, i))]);
      for (double x : xs) to.push_back(vec2(x, y));
    };
    row(slots[0], 1.35, {-0.81, -0.27, 0.27, 0.81});  // y clamped to the table
    row(slots[0], 0.25, {-0.8, -0.4, 0.0, 0.4, 0.8});
    row(slots[1], 0.25, {-0.86, -0.3, 0.3, 0.86});
    row(slots[1], -0.12, {-0.58, 0.0, 0.58});
    for (const bool floor : {false, true}) {
      std::vector<int> objects;
      for (int k = 0; k < count; ++k)
        if (kinds[k].on_floor == floor) objects.push_back(k);
      std::stable_sort(objects.begin(), objects.end(),
                       [&](int a, int b) { return radius[std::size_t(a)] > radius[std::size_t(b)]; });
      for (std::size_t i = 0; i < objects.size(); ++i) slot_of[std::size_t(objects[i])] = int(i);
    }
  }
  std::vector<bool> slot_taken[2] = {std::vector<bool>(slots[0].size()), std::vector<bool>(slots[1].size())};

  // Initial rest poses, each clear of the objects placed before it.
  for (int k = 0; k < count; ++k) {
    ObjectPlan& p = plans[std::size_t(k)];
    const Kind& kind = kinds[k];
    p.radius = radius[std::size_t(k)];
    p.z_rest = (kind.on_floor ? 0.0 : table_top) + kind.half_height;
    if (kind.on_floor && crowded) {
      p.x_lo = -0.9, p.x_hi = 0.9, p.y_lo = -0.3, p.y_hi = 0.4;
    } else if (kind.on_floor) {
      p.x_lo = -0.8, p.x_hi = 0.8, p.y_lo = -0.25, p.y_hi = 0.05;
    } else {
      p.x_lo = -1.1 + p.radius, p.x_hi = 1.1 - p.radius, p.y_lo = 0.25 + p.radius, p.y_hi = 1.35 - p.radius;
    }
    HashRng rng(seed, 1000 + std::uint64_t(k));
    bool placed = false;
    if (crowded) {
      const int own = slot_of[std::size_t(k)];
      auto& taken = slot_taken[kind.on_floor ? 1 : 0];
      for (int i = 0; i <= int(taken.size()) && !placed; ++i) {
        const int slot = i == 0 ? own : i - 1;  // its own first, then the free ones
        if (taken[std::size_t(slot)] || (i > 0 && slot == own)) continue;
        const Vec2<double> at = slots[kind.on_floor ? 1 : 0][std::size_t(slot)];
        for (int attempt = 0; attempt < 50 && !placed; ++attempt) {
          ObjectPlan c = p;
          c.x = std::clamp(at.x() + rng.uniform(-0.02, 0.02), p.x_lo, p.x_hi);
          c.y = std::clamp(at.y() + rng.uniform(-0.02, 0.02), p.y_lo, p.y_hi);
          c.yaw = rng.uniform(-pi, pi);
          if (fits(k, k, 0, c)) p = c, placed = true, taken[std::size_t(slot)] = true;
        }
      }
    }
    for (int attempt = 0; attempt < 2000 && !placed; ++attempt) {
      ObjectPlan c = p;
      c.x = rng.uniform(p.x_lo, p.x_hi), c.y = rng.uniform(p.y_lo, p.y_hi), c.yaw = rng.uniform(-pi, pi);
      if (fits(k, k, 0, c)) p = c, placed = true;
    }
    emfusion::detail::require(placed, "make_dynamic_room",
                              "could not place object " + std::to_string(k) + " in view without overlap");
    update_track(k, 0);
  }

  // Motion segments, in order of start frame.
  std::vector<int> next_start(static_cast<std::size_t>(count));
  std::vector<HashRng> rngs;
  for (int k = 0; k < count; ++k) {
    rngs.emplace_back(seed, 2000 + std::uint64_t(k));
    next_start[std::size_t(k)] = rngs.back().integer(15, 45) + 5 * k;  // everyone starts at rest
  }
  for (;;) {
    int k = -1;
    for (int j = 0; j < count; ++j)
      if (next_start[std::size_t(j)] < frames - 1 && (k < 0 || next_start[std::size_t(j)] < next_start[std::size_t(k)]))
        k = j;
    if (k < 0) break;
    ObjectPlan& p = plans[std::size_t(k)];
    HashRng& rng = rngs[std::size_t(k)];
    const int f0 = next_start[std::size_t(k)];
    const ObjectPlan::State s = p.state(f0);
    int end = -1;
    for (int attempt = 0; attempt < 60 && end < 0; ++attempt) {
      Motion m;
      m.f0 = f0;
      m.x0 = s.x, m.y0 = s.y, m.yaw0 = s.yaw;
      // Shorter moves after many rejections: crowded objects still move.
      const double distance = rng.uniform(0.15, attempt < 20 ? 0.5 : 0.3), heading = rng.uniform(-pi, pi);
      m.x1 = s.x + distance * std::cos(heading), m.y1 = s.y + distance * std::sin(heading);
      const double turn = rng.uniform(20, 60) * pi / 180;
      m.yaw1 = s.yaw + (rng.bernoulli(0.5) ? turn : -turn);
      m.lift = rng.uniform(0.03, 0.1);
      // Tilting by t lowers the lowest point by at most radius * t: lift more.
      m.tilt = rng.uniform() * std::fmin(0.2, m.lift / (1.3 * p.radius));
      m.tilt_direction = rng.uniform(-pi, pi);
      if (m.x1 < p.x_lo || m.x1 > p.x_hi || m.y1 < p.y_lo || m.y1 > p.y_hi) continue;
      // Peak speeds of the profiles: 1.875 d / T for minimum jerk, pi h / T for the bump.
      const double linear = std::sqrt(std::pow(1.875 * distance, 2) + std::pow(pi * m.lift, 2)) / max_speed;
      const double angular = (1.875 * turn + pi * m.tilt) / max_turn_rate;
      m.f1 = f0 + std::max(20, int(std::ceil(std::fmax(linear, angular) * fps)));
      ObjectPlan candidate = p;
      candidate.motions.push_back(m);
      if (fits(k, count, f0, candidate)) {
        p = candidate, end = m.f1;
        update_track(k, f0);
      }
    }
    next_start[std::size_t(k)] = (end < 0 ? f0 : end) + rng.integer(10, 40);
  }
  return plans;
}

}  // namespace detail::room

/// A room with a table and furniture, `moving_objects` objects (none: a
/// static room) on the table and the floor in front of it that start at
/// rest and then move (eased segments of up to 0.5 m and 60 degrees, peak
/// 0.35 m/s and 50 deg/s, lifted and tilted on the way, with rests in
/// between), never overlapping and kept in view, and a hand-held camera
/// 1.8-2.8 m from them (params.camera_path: slow, or with fast segments).
/// Object k is "<class>_<k+1>": car, cup, book, backpack, teddy_bear,
/// potted_plant, laptop, bottle, and in rooms of more than 8 (up to 16)
/// bowl, handbag, cup, suitcase, book, cat, car, bottle (the repeated
/// classes smaller). Rooms of up to 8 objects do not depend on the kinds
/// after the eighth; rooms of more start every object at a slot of its own
/// (detail::room::plan_objects), and their floor objects use more of the
/// floor.
template <class S>
DynamicScene<S> make_dynamic_room(const DynamicSceneParams& params = {}) {
  const char* where = "make_dynamic_room";
  emfusion::detail::require(
      params.camera_path == CameraPath::hand_held || params.camera_path == CameraPath::hand_held_fast, where,
      "camera_path must be hand_held or hand_held_fast, got " + std::to_string(int(params.camera_path)));
  const PinholeCamera<double> camera = detail::scene_camera(params, max_room_objects, where);
  std::vector<SE3<double>> T_world_camera, T_camera_world;
  const bool fast = params.camera_path == CameraPath::hand_held_fast;
  const detail::room::FastPath fast_path =
      fast && params.moving_camera ? detail::room::plan_fast_path(params.seed, (params.frames - 1) / detail::room::fps)
                                   : detail::room::FastPath{};
  for (int i = 0; i < params.frames; ++i) {
    const double t = params.moving_camera ? i / detail::room::fps : 0.0;
    T_world_camera.push_back(fast ? fast_path.pose(t) : detail::room::camera_pose_at(t));
    T_camera_world.push_back(T_world_camera.back().inverse());
  }

  std::vector<MovingObject<S>> objects;
  std::vector<double> radius;
  for (int k = 0; k < params.moving_objects; ++k) {
    MovingObject<S> o;
    o.class_name = detail::room::kinds[k].class_name;
    o.name = o.class_name + "_" + std::to_string(k + 1);
    o.shapes = detail::room::kind_shapes<S>(k);
    double r = 0;
    for (const Shape<S>& s : o.shapes) r = std::fmax(r, detail::bounding_radius(s));
    radius.push_back(r);
    objects.push_back(std::move(o));
  }
  const auto plans =
      detail::room::plan_objects(params.moving_objects, params.frames, params.seed, camera, T_camera_world, radius);
  for (int k = 0; k < params.moving_objects; ++k)
    for (int i = 0; i < params.frames; ++i)
      objects[std::size_t(k)].T_world_object.push_back(plans[std::size_t(k)].pose(i));

  return DynamicScene<S>(camera.template cast<S>(), detail::room::static_shapes<S>(), std::move(objects),
                         std::move(T_world_camera), params.noise, params.seed, detail::room::fps);
}

namespace detail::corridor {

using room::fps;
using room::pi;
constexpr double length = 15;           // m, x in [-1.5, 13.5]
constexpr double half_width = 1.5;      // m, y in [-1.5, 1.5]
constexpr double walk = 11;             // m the camera travels, from x = 0.5
constexpr double ramp = 0.1;            // share of the walk spent speeding up (and slowing down)
constexpr double table_x[3] = {1.5, 5.5, 9.5};  // table centres; tops span x +- 1.1, y in [0.6, 1.3]
constexpr double table_top = room::table_top;
// Table kinds of detail::room::kinds, in the order objects are created:
// car, cup, book, teddy bear, laptop, and the car again.
constexpr int object_kind[6] = {0, 1, 2, 4, 6, 0};

/// Share of the walk done at u in [0, 1]: speed sin^2-eased from rest over
/// the first and last `ramp` of the time, constant between.
inline double walked(double u) {
  u = std::fmin(1.0, std::fmax(0.0, u));
  const auto start = [](double v) { return v / 2 - ramp / (2 * pi) * std::sin(pi * v / ramp); };
  const double d = u < ramp ? start(u) : u > 1 - ramp ? (1 - ramp) - start(1 - u) : ramp / 2 + (u - ramp);
  return d / (1 - ramp);
}

/// The walk at time t of a sequence lasting `duration` seconds: the eye
/// 0.8 m from the corridor's middle towards the bare wall, at eye height,
/// looking at the tables' wall a little ahead of itself, with a hand-held
/// sway.
inline SE3<double> camera_pose_at(double t, double duration) {
  const double x = 0.5 + walk * walked(duration > 0 ? t / duration : 0.0);
  const double w = 2 * pi;
  const Vec3<double> eye = vec3(x, -0.8 + 0.08 * std::sin(w * t / 7), 1.55 + 0.05 * std::sin(w * t / 5 + 1));
  const Vec3<double> target = vec3(x + 0.7 + 0.25 * std::sin(w * t / 9), 1.1, 0.55 + 0.12 * std::sin(w * t / 6));
  return look_at(eye, target, vec3(0.0, 0.0, 1.0));
}

/// The corridor: floor, ceiling, two long walls and the end walls; along the
/// +y wall three tables with cabinets and shelves of different heights
/// between them; along the -y wall a few boxes.
template <class S>
std::vector<Shape<S>> static_shapes() {
  auto v = [](double x, double y, double z) { return vec3(S(x), S(y), S(z)); };
  auto plane = [&](Vec3<S> on, Vec3<S> inside, Vec3<S> up) { return make_plane(look_at(on, inside, up)); };
  auto box = [&](double x, double y, double z, double hx, double hy, double hz, double yaw = 0) {
    return make_box(SE3<S>(so3_exp(v(0, 0, yaw)), v(x, y, z)), v(hx, hy, hz));
  };
  const Vec3<S> up = v(0, 0, 1);
  const double x0 = -1.5, x1 = x0 + length, xm = (x0 + x1) / 2;
  std::vector<Shape<S>> shapes = {
      make_plane(SE3<S>::identity()),                 // floor, z = 0
      plane(v(xm, 0, 2.8), v(xm, 0, 0), v(1, 0, 0)),  // ceiling
      plane(v(xm, half_width, 1.4), v(xm, 0, 1.4), up),  // the tables' wall
      plane(v(xm, -half_width, 1.4), v(xm, 0, 1.4), up),
      plane(v(x0, 0, 1.4), v(xm, 0, 1.4), up),  // end walls
      plane(v(x1, 0, 1.4), v(xm, 0, 1.4), up),
  };
  for (double x : table_x) shapes.push_back(box(x, 0.95, table_top - 0.02, 1.1, 0.35, 0.02));  // table tops
  // Between and beside the tables, against the wall: furniture of different
  // heights and depths, so that the wall shows structure along x everywhere.
  shapes.push_back(box(-0.6, 1.3, 0.9, 0.3, 0.2, 0.9));    // tall shelf
  shapes.push_back(box(3.5, 1.25, 0.45, 0.45, 0.25, 0.45));  // cabinet
  shapes.push_back(box(3.6, 1.2, 1.3, 0.2, 0.2, 0.35, 0.4));  // box on it, turned
  shapes.push_back(box(7.5, 1.3, 0.7, 0.35, 0.2, 0.7));     // shelf
  shapes.push_back(make_cylinder(SE3<S>::translation(v(7.0, 1.0, 0.3)), S(0.2), S(0.3)));  // bin
  shapes.push_back(box(11.4, 1.25, 0.35, 0.3, 0.25, 0.35, -0.3));  // crate
  shapes.push_back(box(12.4, 1.3, 1.0, 0.35, 0.2, 1.0));           // tall cabinet
  // Along the bare wall, seen when the view swings.
  shapes.push_back(box(2.5, -1.3, 0.4, 0.4, 0.2, 0.4));
  shapes.push_back(box(8.5, -1.25, 0.6, 0.3, 0.25, 0.6, 0.2));
  return shapes;
}

/// Object k's plan: on table k / 2 (its left or right half, k % 2), at rest
/// until the camera comes near, then one or two eased moves (up to 0.3 m and
/// 60 degrees, lifted and tilted, peak 0.35 m/s and 50 deg/s) while the
/// camera passes, then at rest again. Halves are 0.2 m apart and an object
/// keeps its radius inside its half: objects never overlap.
inline room::ObjectPlan plan_object(int k, int frames, std::uint64_t seed, double radius,
                                    const std::vector<SE3<double>>& T_world_camera) {
  room::ObjectPlan p;
  const room::Kind& kind = room::kinds[object_kind[k]];
  const double xc = table_x[k / 2];
  p.radius = radius;
  p.z_rest = table_top + kind.half_height;
  p.x_lo = k % 2 == 0 ? xc - 1.05 + radius : xc + 0.1 + radius;
  p.x_hi = k % 2 == 0 ? xc - 0.1 - radius : xc + 1.05 - radius;
  p.y_lo = 0.6 + radius, p.y_hi = 1.3 - radius;
  HashRng rng(seed, 3000 + std::uint64_t(k));
  p.x = rng.uniform(p.x_lo, p.x_hi), p.y = rng.uniform(p.y_lo, p.y_hi), p.yaw = rng.uniform(-pi, pi);
  // Frames in which the camera looks at the object's half of the table.
  int first = -1, last = -1;
  for (int f = 0; f < frames; ++f) {
    const Vec3<double> e = T_world_camera[std::size_t(f)].translation();
    if (std::fabs(e.x() + 0.7 - 0.5 * (p.x_lo + p.x_hi)) < 1.2) {
      if (first < 0) first = f;
      last = f;
    }
  }
  if (first < 0) return p;
  int f0 = first + rng.integer(5, 20);
  for (int move = 0; move < 2; ++move) {
    const room::ObjectPlan::State s = p.state(f0);
    for (int attempt = 0; attempt < 60; ++attempt) {
      room::Motion m;
      m.f0 = f0;
      m.x0 = s.x, m.y0 = s.y, m.yaw0 = s.yaw;
      const double distance = rng.uniform(0.1, 0.3), heading = rng.uniform(-pi, pi);
      m.x1 = s.x + distance * std::cos(heading), m.y1 = s.y + distance * std::sin(heading);
      if (m.x1 < p.x_lo || m.x1 > p.x_hi || m.y1 < p.y_lo || m.y1 > p.y_hi) continue;
      const double turn = rng.uniform(20, 60) * pi / 180;
      m.yaw1 = s.yaw + (rng.bernoulli(0.5) ? turn : -turn);
      m.lift = rng.uniform(0.03, 0.08);
      m.tilt = rng.uniform() * std::fmin(0.2, m.lift / (1.3 * radius));
      m.tilt_direction = rng.uniform(-pi, pi);
      const double linear =
          std::sqrt(std::pow(1.875 * distance, 2) + std::pow(pi * m.lift, 2)) / room::max_speed;
      const double angular = (1.875 * turn + pi * m.tilt) / room::max_turn_rate;
      m.f1 = f0 + std::max(20, int(std::ceil(std::fmax(linear, angular) * fps)));
      if (m.f1 > last || m.f1 >= frames) continue;  // another draw may be shorter
      p.motions.push_back(m);
      f0 = m.f1 + rng.integer(5, 15);
      break;
    }
  }
  return p;
}

}  // namespace detail::corridor

/// A corridor 15 m long (x in [-1.5, 13.5], y in [-1.5, 1.5], 2.8 m high)
/// with three tables and furniture along its +y wall, walked along by a
/// hand-held camera that travels 11 m (from x = 0.5, eased from and to rest,
/// about 0.6 m/s on 20 s) looking at the tables; `moving_objects` (0..6)
/// objects on the tables, two per table, at rest until the camera comes
/// near, then moved once or twice while it passes (up to 0.3 m and 60
/// degrees; eased, lifted and tilted). Object k is "<class>_<k+1>": car,
/// cup, book, teddy_bear, laptop, car. A world no 5 m volume around the first
/// camera holds: the scene of the sparse background (docs/volumes.md).
/// params.camera_path is not used.
template <class S>
DynamicScene<S> make_dynamic_corridor(const DynamicSceneParams& params = {}) {
  const PinholeCamera<double> camera = detail::scene_camera(params, 6, "make_dynamic_corridor");
  const double duration = (params.frames - 1) / detail::corridor::fps;
  std::vector<SE3<double>> T_world_camera;
  for (int i = 0; i < params.frames; ++i)
    T_world_camera.push_back(
        detail::corridor::camera_pose_at(params.moving_camera ? i / detail::corridor::fps : 0.0, duration));
  std::vector<MovingObject<S>> objects;
  for (int k = 0; k < params.moving_objects; ++k) {
    const int kind = detail::corridor::object_kind[k];
    MovingObject<S> o;
    o.class_name = detail::room::kinds[kind].class_name;
    o.name = o.class_name + "_" + std::to_string(k + 1);
    o.shapes = detail::room::kind_shapes<S>(kind);
    double r = 0;
    for (const Shape<S>& shape : o.shapes) r = std::fmax(r, detail::bounding_radius(shape));
    const detail::room::ObjectPlan plan =
        detail::corridor::plan_object(k, params.frames, params.seed, r, T_world_camera);
    for (int i = 0; i < params.frames; ++i) o.T_world_object.push_back(plan.pose(i));
    objects.push_back(std::move(o));
  }
  return DynamicScene<S>(camera.template cast<S>(), detail::corridor::static_shapes<S>(), std::move(objects),
                         std::move(T_world_camera), params.noise, params.seed, detail::corridor::fps);
}

/// The scene params.layout names: make_dynamic_room or make_dynamic_corridor.
template <class S>
DynamicScene<S> make_dynamic_scene(const DynamicSceneParams& params = {}) {
  if (params.layout == SceneLayout::corridor) return make_dynamic_corridor<S>(params);
  emfusion::detail::require(params.layout == SceneLayout::room, "make_dynamic_scene",
                            "layout must be room or corridor, got " + std::to_string(int(params.layout)));
  return make_dynamic_room<S>(params);
}

/// A dynamic scene as a FrameSource (float depth on the host, noisy).
class SyntheticSequence {
 public:
  explicit SyntheticSequence(const DynamicSceneParams& params = {}) : scene_(make_dynamic_scene<float>(params)) {}
  explicit SyntheticSequence(DynamicScene<float> scene) : scene_(std::move(scene)) {}

  std::size_t size() const { return std::size_t(scene_.frame_count()); }
  double timestamp(std::size_t i) const { return scene_.timestamp(checked(i)); }
  Image<float, Host> depth(std::size_t i) const {
    Image<float, Host> d;
    scene_.render(checked(i), d);
    return d;
  }
  PinholeCamera<double> camera() const { return scene_.camera().template cast<double>(); }
  const DynamicScene<float>& scene() const { return scene_; }

 private:
  int checked(std::size_t i) const {
    emfusion::detail::require(i < size(), "SyntheticSequence",
                              "frame " + std::to_string(i) + " is not in 0.." + std::to_string(size() - 1));
    return int(i);
  }
  DynamicScene<float> scene_;
};

}  // namespace emfusion::sim

// A weak pull of a pose problem towards a given pose: six terms appended to
// any PoseTerms, so that the directions its data cannot observe (the axis
// of a cylinder seen from its side, the plane of a flat patch, the turn of
// a ball) stay where the prior pose puts them while the data decides every
// direction it observes. With D = T P^-1 (T the pose solved for, P the
// prior's, both T_volume_camera), the residuals are the displacement of a
// point c (the volume's centre, volume frame) by D, and `radius` times the
// rotation vector of D: how far D moves the object's centre and the points
// `radius` from it. Each takes the fixed weight `weight`, the number of
// perfectly confident surface points it counts as along its direction: a
// few dozen against the thousands an object's surface gives where it is
// observed.
#pragma once

#include <cmath>

#include "emfusion/core/host_device.hpp"
#include "emfusion/core/math.hpp"
#include "emfusion/core/se3.hpp"

namespace emfusion {

template <class S>
struct PosePrior {
  SE3<S> pose;       ///< P: where the problem is pulled to
  Vec3<S> centre{};  ///< c: the point whose displacement counts (the problem's frame)
  S radius = S(0);   ///< metres a rotation is measured at (rotation residual = radius x angle)
  S weight = S(0);   ///< fixed weight of each of the six terms; 0: no prior

  /// A prior of weight `weight` for a problem in a box [0, extent] (an
  /// object's volume): measured at the box's centre, a rotation at half
  /// the box's diagonal over sqrt(3) (its mean half side); the pose is set
  /// by towards().
  static PosePrior in_box(const Vec3<S>& extent, S weight) {
    PosePrior p;
    p.centre = S(0.5) * extent;
    p.radius = S(0.5) * norm(extent) / std::sqrt(S(3));
    p.weight = weight;
    return p;
  }

  /// The same prior pulling towards `P`.
  PosePrior towards(const SE3<S>& P) const {
    PosePrior p = *this;
    p.pose = P;
    return p;
  }
};

/// `terms` with a PosePrior's six terms after its own (none with weight 0).
template <class P, class S>
struct WithPosePrior {
  P terms;
  PosePrior<S> prior;

  EMF_HD int term_count() const { return terms.term_count() + (prior.weight > S(0) ? 6 : 0); }

  EMF_HD bool term(int i, const SE3<S>& T, S& r, Vec6<S>& J, S& w) const {
    // Without a prior (the camera, objects by default) the terms' own call
    // alone: counting them again per term would repeat their grid's divisions.
    if (!(prior.weight > S(0))) return terms.term(i, T, r, J, w);
    const int n = terms.term_count();
    if (i < n) return terms.term(i, T, r, J, w);
    const int k = i - n;
    const SE3<S> D = T * prior.pose.inverse();
    // Left perturbation exp(xi) D: the centre moves by v + w x (D c), the
    // rotation vector by w (to first order).
    J = Vec6<S>::zero();
    if (k < 3) {
      const Vec3<S> moved = D * prior.centre;
      r = (moved - prior.centre)[k];
      const auto Jc = SE3<S>::left_jacobian_of_action(moved);
      for (int j = 0; j < 6; ++j) J[j] = Jc(k, j);
    } else {
      r = prior.radius * so3_log(D.rotation())[k - 3];
      J[k] = prior.radius;
    }
    w = prior.weight;
    return true;
  }
};

}  // namespace emfusion

// How SDF alignment (solve/sdf_alignment.hpp) and the likelihood models
// (likelihood/measurement_likelihood.hpp) name the volume they read: by a
// template parameter that is either the view type of any volume (a
// TsdfSampler: TsdfView, SparseTsdfView) or, as before volumes had a concept,
// the storage scalar of a dense volume, read through TsdfView<S, const Store>.
// So `SdfAlignmentTerms<S, Store>` and `PaperLikelihood<S>` keep their
// meaning and types, and `PaperLikelihood<S, SparseTsdfView<S, const S>>`
// reads a sparse volume.
#pragma once

#include <type_traits>
#include <utility>

#include "emfusion/volume/tsdf_volume.hpp"
#include "emfusion/volume/volume_view.hpp"

namespace emfusion {

/// The view type a volume parameter P names: P itself when it is a
/// TsdfSampler of S, else the dense view of storage scalar P.
template <class S, class P>
using volume_sampler_t = std::conditional_t<TsdfSampler<P, S>, P, TsdfView<S, const P>>;

namespace detail {
template <class View>
struct volume_parameter {
  using type = View;
};
template <class S, class Store>
struct volume_parameter<TsdfView<S, const Store>> {
  using type = Store;
};
}  // namespace detail

/// The parameter that names view type `View`: the storage scalar for a
/// read-only dense view (so that the dense types stay those they always
/// were), the view itself otherwise. volume_sampler_t undoes it.
template <class View>
using volume_parameter_t = typename detail::volume_parameter<View>::type;

/// The parameter of the read-only view of an owning volume (TsdfVolumeType).
template <class Volume>
using volume_parameter_of_t = volume_parameter_t<decltype(std::declval<const Volume&>().view())>;

/// An owning TSDF volume (TsdfVolumeType) whose work runs on backend B.
template <class Volume, class S, class B>
concept TsdfVolumeOn = TsdfVolumeType<Volume, S> &&
    std::is_same_v<std::remove_cvref_t<decltype(std::declval<const Volume&>().backend())>, B>;

}  // namespace emfusion

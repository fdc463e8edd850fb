// Batched solves (solve/batched_solve.hpp): several SDF alignments solved in
// lock step must end where each solved alone ends, one that has nothing to
// solve must stop without holding up the others, and a batch's
// linearisation must equal the single one.
#include <cmath>
#include <vector>

#include "emfusion/solve/batched_solve.hpp"
#include "emfusion/solve/sdf_alignment.hpp"
#include "support/catch.hpp"
#include "support/configs.hpp"
#include "support/room.hpp"

using namespace emfusion;
using emfusion::test::Approx;

namespace {

template <class S>
double translation_between(const SE3<S>& a, const SE3<S>& b) {
  return norm((a.inverse() * b).template cast<double>().translation());
}
template <class S>
double degrees_between(const SE3<S>& a, const SE3<S>& b) {
  return norm(so3_log((a.inverse() * b).template cast<double>().rotation())) * 180.0 / M_PI;
}

/// The room at a known pose, its terms over the whole image, and that pose
/// in the volume (what the solves should find).
template <class S, class B>
struct RoomTerms : test::RoomAtKnownPose<S, B> {
  using Terms = sdf_alignment_terms_t<S, TsdfVolume<S, B>>;
  Terms all = make_sdf_alignment(this->volume, this->points, static_cast<const Image<S, B>*>(nullptr));
  SE3<S> T_true = this->volume.pose().inverse() * this->truth;
};

}  // namespace

TEMPLATE_LIST_TEST_CASE("A batch of alignments ends where each alone ends", "[solve]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const RoomTerms<S, B> room;
  using Terms = typename RoomTerms<S, B>::Terms;
  Terms corner = room.all;  // a quarter of the image: fewer terms, other iterations
  corner.box = PixelBox{0, 0, room.points.width() / 2, room.points.height() / 2};
  Terms strided = room.all;
  strided.stride = 3;
  Terms nothing = room.all;  // one pixel: too few terms, stops at once
  nothing.box = PixelBox{0, 0, 1, 1};

  const S deg = S(M_PI / 180);
  const std::vector<Vec6<S>> offsets = {
      Vec6<S>{{S(0.05), S(-0.05), S(0.06), S(4) * deg, S(-5) * deg, S(6) * deg}},
      Vec6<S>{{S(0.02), S(0), S(0), S(0), S(0), S(0)}},
      Vec6<S>{{S(0), S(0), S(0), S(0), S(10) * deg, S(0)}},
      Vec6<S>{{S(-0.07), S(0.03), S(-0.07), S(-6) * deg, S(6) * deg, S(-5) * deg}},
  };
  std::vector<BatchedProblem<Terms, HuberNorm<S>>> problems = {
      {room.all, room.huber}, {corner, room.huber}, {strided, room.huber}, {nothing, room.huber}};
  std::vector<SE3<S>> starts;
  for (const auto& o : offsets) starts.push_back(SE3<S>::exp(o) * room.T_true);

  LevenbergMarquardtParams lm;
  lm.tau = 1e-3;
  lm.eps2 = 1e-6;
  const B& backend = room.volume.backend();
  BatchedSolveWorkspace<S, B> ws;
  for (const int run : {1, 2}) {  // the second run reuses the workspace (on a device, its graph)
    std::vector<SolveReport> reports;
    const std::vector<SE3<S>> batched = solve_batch(backend, problems, starts, lm, reports, ws);
    REQUIRE(batched.size() == problems.size());
    REQUIRE(reports.size() == problems.size());
    for (std::size_t p = 0; p < problems.size(); ++p) {
      LinearizationCache<S, B> cache;
      SolveReport alone_report;
      const auto lin = [&](const SE3<S>& T, const SE3<S>* reference) {
        return linearize(backend, problems[p].terms, room.huber, T, reference, cache);
      };
      const SE3<S> alone = levenberg_marquardt(lin, starts[p], lm, &alone_report);
      INFO("problem " << p << ", run " << run << ": batched " << reports[p].iterations
                      << " iterations (" << to_string(reports[p].reason) << "), alone " << alone_report.iterations
                      << " (" << to_string(alone_report.reason) << "); "
                      << translation_between(batched[p], alone) * 1000 << " mm apart");
      CHECK(reports[p].reason == alone_report.reason);
      CHECK(reports[p].converged() == alone_report.converged());
      CHECK(reports[p].terms == alone_report.terms);
      CHECK(translation_between(batched[p], alone) < 2e-4);
      CHECK(degrees_between(batched[p], alone) < 0.02);
      if (p < 3) {  // and all three where they should be
        CHECK(translation_between(batched[p], room.T_true) < 3e-3);
        CHECK(std::abs(reports[p].iterations - alone_report.iterations) <= 3);
      }
    }
    CHECK(reports[3].reason == StopReason::too_few_terms);
    CHECK(reports[3].iterations == 0);
    CHECK(max_abs_diff(batched[3].matrix(), starts[3].orthonormalized().matrix()) < S(1e-5));
  }
  // Fewer problems (fewer segments) run through the same graph, to the same poses.
  {
    std::vector<SolveReport> reports, again;
    const auto all = solve_batch(backend, problems, starts, lm, reports, ws);
    const auto two = solve_batch(backend, decltype(problems)(problems.begin(), problems.begin() + 2),
                                 std::vector<SE3<S>>(starts.begin(), starts.begin() + 2), lm, again, ws);
    REQUIRE(two.size() == 2);
    for (std::size_t p = 0; p < 2; ++p) {
      CHECK(max_abs_diff(two[p].matrix(), all[p].matrix()) == S(0));
      CHECK(again[p].iterations == reports[p].iterations);
    }
    CHECK(ws.loop.builds() == (B::is_device ? 1 : 0));
  }

  // A batch of none is no work.
  std::vector<SolveReport> reports;
  CHECK(solve_batch(backend, decltype(problems){}, std::vector<SE3<S>>{}, lm, reports, ws).empty());
  CHECK(reports.empty());
  CHECK_THROWS_WITH(solve_batch(backend, problems, std::vector<SE3<S>>(1), lm, reports, ws),
                    EMF_CONTAINS("need one start per problem"));
}

TEMPLATE_LIST_TEST_CASE("A batch's linearisation equals each problem's", "[solve]", emfusion::test::AllConfigs) {
  using S = typename TestType::Scalar;
  using B = typename TestType::Backend;
  const RoomTerms<S, B> room;
  using Terms = typename RoomTerms<S, B>::Terms;
  Terms strided = room.all;
  strided.stride = 2;
  const SE3<S> off = SE3<S>::exp(Vec6<S>{{S(0.01), S(0), S(-0.02), S(0), S(0.02), S(0)}}) * room.T_true;
  std::vector<BatchedProblem<Terms, HuberNorm<S>>> problems = {
      {room.all, room.huber}, {strided, room.huber}, {room.all, room.huber}};
  std::vector<LinearizationRequest<S>> requests(3);
  requests[0].T = off, requests[0].reference = room.T_true, requests[0].has_reference = 1;
  requests[1].T = room.T_true;
  requests[2].T = room.T_true, requests[2].reference = off, requests[2].has_reference = 1;
  for (auto& q : requests) q.active = 1;
  BatchedSolveWorkspace<S, B> ws;
  const std::vector<NormalEquations6> batch = linearize_batch(room.volume.backend(), problems, requests, ws);
  REQUIRE(batch.size() == 3);
  for (std::size_t p = 0; p < 3; ++p) {
    const auto& q = requests[p];
    const NormalEquations6 one =
        linearize(room.volume.backend(), problems[p].terms, room.huber, q.T,
                  q.has_reference ? &q.reference : nullptr);
    INFO("problem " << p);
    CHECK(batch[p].terms == one.terms);
    CHECK(batch[p].terms > 1000);
    CHECK(batch[p].cost == Approx(one.cost).epsilon(1e-9));
    CHECK(batch[p].shared_cost == Approx(one.shared_cost).epsilon(1e-9));
    CHECK(batch[p].shared_reference_cost == Approx(one.shared_reference_cost).epsilon(1e-9));
    for (int i = 0; i < 6; ++i) CHECK(batch[p].g[i] == Approx(one.g[i]).epsilon(1e-9).margin(1e-12));
    for (int i = 0; i < 21; ++i) CHECK(batch[p].H[i] == Approx(one.H[i]).epsilon(1e-9).margin(1e-12));
  }
  requests.pop_back();
  CHECK_THROWS_WITH(linearize_batch(room.volume.backend(), problems, requests, ws),
                    EMF_CONTAINS("need one request per problem"));
}

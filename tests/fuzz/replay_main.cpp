// Replays fuzz inputs without libFuzzer, in every normal build: one
// executable for all targets (each fuzz_<target>.cpp is included below with
// its LLVMFuzzerTestOneInput renamed, so the targets compile as one unit).
//
//   emfusion_fuzz_replay <target> <file-or-directory>...
//
// feeds every file (directories: every regular file in them, sorted by
// name) to the target's entry point. A broken invariant traps, so a failing
// input stops the run with a crash that names the file first. A directory
// that does not exist counts as empty (regressions/<target>/ holds files
// only once a crash was found), but the run fails if no input at all was
// replayed (a wrong path would otherwise pass).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#define LLVMFuzzerTestOneInput replay_tum_trajectory
#include "fuzz_tum_trajectory.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_tum_list
#include "fuzz_tum_list.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_calibration
#include "fuzz_calibration.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_intrinsics
#include "fuzz_intrinsics.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_masks
#include "fuzz_masks.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_config
#include "fuzz_config.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_klg
#include "fuzz_klg.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_exr
#include "fuzz_exr.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_png
#include "fuzz_png.cpp"
#undef LLVMFuzzerTestOneInput
#define LLVMFuzzerTestOneInput replay_checkpoint
#include "fuzz_checkpoint.cpp"
#undef LLVMFuzzerTestOneInput

namespace {

using EntryPoint = int (*)(const std::uint8_t*, std::size_t);

struct Target {
  const char* name;
  EntryPoint run;
};

constexpr Target targets[] = {
    {"tum_trajectory", replay_tum_trajectory},
    {"tum_list", replay_tum_list},
    {"calibration", replay_calibration},
    {"intrinsics", replay_intrinsics},
    {"masks", replay_masks},
    {"config", replay_config},
    {"klg", replay_klg},
    {"exr", replay_exr},
    {"png", replay_png},
    {"checkpoint", replay_checkpoint},
};

bool replay(EntryPoint run, const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    std::fprintf(stderr, "emfusion_fuzz_replay: cannot read '%s'\n", file.string().c_str());
    return false;
  }
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::fprintf(stderr, "replaying '%s' (%zu bytes)\n", file.string().c_str(), bytes.size());
  std::fflush(stderr);
  // A copy of exactly the input's size, as libFuzzer passes it (so that
  // AddressSanitizer sees a read past the end).
  std::vector<std::uint8_t> data(bytes.begin(), bytes.end());
  run(data.empty() ? nullptr : data.data(), data.size());
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  const auto usage = [&] {
    std::fprintf(stderr, "usage: %s <target> <file-or-directory>...\ntargets:", argv[0]);
    for (const Target& t : targets) std::fprintf(stderr, " %s", t.name);
    std::fprintf(stderr, "\n");
    return 2;
  };
  if (argc < 3) return usage();
  const Target* target = nullptr;
  for (const Target& t : targets)
    if (std::strcmp(argv[1], t.name) == 0) target = &t;
  if (!target) return usage();

  std::size_t replayed = 0;
  for (int a = 2; a < argc; ++a) {
    const fs::path path(argv[a]);
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
      std::vector<fs::path> files;
      for (const fs::directory_entry& e : fs::directory_iterator(path))
        if (e.is_regular_file()) files.push_back(e.path());
      std::sort(files.begin(), files.end());
      for (const fs::path& f : files) {
        if (!replay(target->run, f)) return 1;
        ++replayed;
      }
    } else if (fs::exists(path, ec)) {
      if (!replay(target->run, path)) return 1;
      ++replayed;
    } else {
      std::fprintf(stderr, "'%s' does not exist: no inputs from it\n", path.string().c_str());
    }
  }
  std::printf("%s: %zu inputs replayed, no failure\n", target->name, replayed);
  if (replayed == 0) {
    std::fprintf(stderr, "emfusion_fuzz_replay: no input replayed (wrong paths?)\n");
    return 1;
  }
  return 0;
}

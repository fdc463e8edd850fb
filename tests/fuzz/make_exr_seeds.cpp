// Writes the EXR seeds of tests/fuzz/corpus/exr/ that only OpenEXR can make
// (make_seeds.py writes the NONE, ZIPS and ZIP ones from the format's
// description): small depth images in every other compression, tiled and
// mipmapped ones, several channels, so that the fuzzer starts inside each of
// OpenEXR's decoders. Depends on OpenEXR alone; run by hand from the
// repository root after changing it:
//
//   c++ -std=c++17 tests/fuzz/make_exr_seeds.cpp $(pkg-config --cflags --libs OpenEXR) -o /tmp/make_exr_seeds
//   /tmp/make_exr_seeds tests/fuzz/corpus/exr
#include <ImfChannelList.h>
#include <ImfCompression.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <ImfTileDescription.h>
#include <ImfTiledOutputFile.h>
#include <half.h>

#include <cstdio>
#include <exception>
#include <string>
#include <vector>

namespace {

constexpr int width = 8, height = 6;

/// Depth in metres with a step, as a sensor sees a box before a wall.
float depth(int x, int y) { return x > 2 && x < 6 && y > 1 ? 0.9f + 0.01f * float(x) : 1.5f + 0.02f * float(y); }

struct Seed {
  const char* name;
  Imf::Compression compression;
  Imf::PixelType type;
  std::vector<const char*> channels;
  int tile = 0;  // 0: scanline
  bool mipmap = false;
};

void write(const std::string& path, const Seed& seed) {
  Imf::Header header(width, height);
  header.compression() = seed.compression;
  for (const char* name : seed.channels) header.channels().insert(name, Imf::Channel(seed.type));
  std::vector<float> floats;
  std::vector<half> halves;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      floats.push_back(depth(x, y));
      halves.push_back(half(depth(x, y)));
    }
  const std::size_t size = seed.type == Imf::HALF ? sizeof(half) : sizeof(float);
  char* data = seed.type == Imf::HALF ? reinterpret_cast<char*>(halves.data()) : reinterpret_cast<char*>(floats.data());
  Imf::FrameBuffer frame;
  // Every channel reads the same samples; smaller mip levels read the first rows.
  for (const char* name : seed.channels) frame.insert(name, Imf::Slice(seed.type, data, size, size * width));
  if (seed.tile == 0) {
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(frame);
    file.writePixels(height);
    return;
  }
  header.setTileDescription(
      Imf::TileDescription(seed.tile, seed.tile, seed.mipmap ? Imf::MIPMAP_LEVELS : Imf::ONE_LEVEL, Imf::ROUND_DOWN));
  Imf::TiledOutputFile file(path.c_str(), header);
  file.setFrameBuffer(frame);
  for (int level = 0; level < file.numLevels(); ++level)
    file.writeTiles(0, file.numXTiles(level) - 1, 0, file.numYTiles(level) - 1, level);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_exr_seeds <folder>\n");
    return 2;
  }
  const std::vector<Seed> seeds = {
      {"openexr_rle_half.exr", Imf::RLE_COMPRESSION, Imf::HALF, {"Z"}},
      {"openexr_piz_float.exr", Imf::PIZ_COMPRESSION, Imf::FLOAT, {"Z"}},
      {"openexr_pxr24_float.exr", Imf::PXR24_COMPRESSION, Imf::FLOAT, {"depth"}},
      {"openexr_b44_half.exr", Imf::B44_COMPRESSION, Imf::HALF, {"Y"}},
      {"openexr_b44a_half.exr", Imf::B44A_COMPRESSION, Imf::HALF, {"Z"}},
      {"openexr_dwaa_rgbz.exr", Imf::DWAA_COMPRESSION, Imf::HALF, {"B", "G", "R", "Z"}},
      {"openexr_dwab_float_r.exr", Imf::DWAB_COMPRESSION, Imf::FLOAT, {"R"}},
      {"openexr_tiled_zip.exr", Imf::ZIP_COMPRESSION, Imf::FLOAT, {"Z"}, 4},
      {"openexr_mipmap_none.exr", Imf::NO_COMPRESSION, Imf::HALF, {"Z"}, 4, true},
  };
  try {
    for (const Seed& seed : seeds) write(std::string(argv[1]) + "/" + seed.name, seed);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "make_exr_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}

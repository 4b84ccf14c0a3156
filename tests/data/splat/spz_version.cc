// Converts a PLY to SPZ of a chosen version with Niantic's own library, so
// visage reads files of the legacy gzip versions as that library writes them.
// Build against github.com/nianticlabs/spz (see make_spz.sh):
//   g++ -O2 -I spz/src/cc spz_version.cc build/libspz.a -lz -lzstd -o spz_version
#include <cstdlib>
#include "load-spz.h"

int main(int argc, char *argv[]) {
  if (argc != 4) return 2;
  spz::UnpackOptions unpack;
  spz::GaussianCloud cloud = spz::loadSplatFromPly(argv[1], unpack);
  spz::PackOptions pack;
  pack.version = std::atoi(argv[3]);
  return spz::saveSpz(cloud, pack, argv[2]) ? 0 : 1;
}

// fusionctl: command-line client of fusiond. Speaks only the wire types (proto/). The tool is
// the library fusion_fusionctl (fusionctl.h), so its tests run it in-process.
#include "fusionctl.h"

int main(int argc, char** argv) { return fusionctl::Run(argc, argv); }

#include "lodstream/lodstream.h"
namespace lodstream {
Result info(const std::string&, const Options&, SceneInfo*) { return {Status::internal, "not yet"}; }
uint64_t peak_rss_bytes() { return 0; }
}

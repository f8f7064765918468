#include "core/status.h"

namespace lodstream {

const char* status_name(Status status) {
  switch (status) {
    case Status::ok: return "ok";
    case Status::usage: return "usage";
    case Status::bad_data: return "bad_data";
    case Status::no_input: return "no_input";
    case Status::internal: return "internal";
    case Status::io_error: return "io_error";
    case Status::cancelled: return "cancelled";
  }
  return "unknown";
}

}  // namespace lodstream

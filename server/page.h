// The job server's pages for people: the jobs with live progress, a form to submit one, links to each
// job's outputs; and the token form a browser gets when the server needs a token it did not send.
#pragma once

#include <string>

namespace lodstream::serve {

const std::string& jobs_page();
const std::string& login_page();

}  // namespace lodstream::serve

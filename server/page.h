// The job server's pages for people: the jobs with live progress, a form to submit one, links to each
// job's outputs; a viewer of a job's tiles or levels; and the token form a browser gets when the server
// needs a token it did not send.
#pragma once

#include <string>

namespace lodstream::serve {

const std::string& jobs_page();
const std::string& login_page();
// GET /viewer?job=ID: a WebGL 2 viewer of a job's 3D Tiles (tiles/tileset.json, tiles chosen by screen-space
// error, content fetched from the server as it is needed) or, without tiles, of lods.glb (a level slider).
const std::string& viewer_page();

}  // namespace lodstream::serve

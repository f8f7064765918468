// HTTP layer of `lodstream serve` on cpp-httplib (Debian libcpp-httplib-dev): OGC API - Processes - Part 1:
// Core (OGC 18-062r2) resources, job output files with HTTP Range (RFC 9110 §14), bearer tokens (RFC 6750),
// and the web page for people (server/page.cpp).
#include "server/serve.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <thread>

#include <httplib.h>

#include "io/text.h"
#include "server/guarded_server.h"
#include "server/jobs.h"
#include "server/page.h"
#include "server/processes.h"

namespace lodstream::serve {
namespace {

namespace fs = std::filesystem;

constexpr size_t kMaxJsonBody = 1 << 20;
constexpr size_t kMaxHeaders = 64;
constexpr size_t kConnectionThreads = 64;
constexpr int kListenBacklog = 1024;

// Compares in time that depends on the expected token's length only, never on where the strings differ.
bool same_token(const std::string& given, const std::string& expected) {
  unsigned char diff = given.size() != expected.size();
  for (size_t i = 0; i < expected.size(); ++i)
    diff |= static_cast<unsigned char>((i < given.size() ? given[i] : 0) ^ expected[i]);
  return diff == 0;
}


// The token the login page keeps in a cookie, so that plain links (report.html, tiles) work in a browser.
std::string cookie_token(const httplib::Request& req) {
  const std::string cookies = req.get_header_value("Cookie");
  const std::string key = "lodstream_token=";
  size_t at = 0;
  while (at < cookies.size()) {
    while (at < cookies.size() && (cookies[at] == ' ' || cookies[at] == ';')) ++at;
    const size_t end = std::min(cookies.find(';', at), cookies.size());
    if (cookies.compare(at, key.size(), key) == 0) return io::text::percent_decode(cookies.substr(at + key.size(), end - at - key.size()));
    at = end;
  }
  return {};
}

bool wants_html(const httplib::Request& req) {
  if (req.has_param("f")) return req.get_param_value("f") == "html";
  const std::string accept = req.get_header_value("Accept");
  const size_t html = accept.find("text/html"), json = accept.find("application/json");
  return html != std::string::npos && (json == std::string::npos || html < json);
}

const char* status_title(int status) {
  switch (status) {
    case 400: return "Bad Request";
    case 401: return "Unauthorized";
    case 404: return "Not Found";
    case 411: return "Length Required";
    case 413: return "Content Too Large";
    case 415: return "Unsupported Media Type";
    case 416: return "Range Not Satisfiable";
    case 431: return "Request Header Fields Too Large";
    case 500: return "Internal Server Error";
    case 503: return "Service Unavailable";
    case 507: return "Insufficient Storage";
    default: return "Error";
  }
}

void send_json(httplib::Response& res, int status, const ojson& body) {
  res.status = status;
  res.set_content(body.dump(2), "application/json");
}

// OGC API exceptions (RFC 7807 problem details), e.g. no-such-job, no-such-process, result-not-ready.
void send_problem(httplib::Response& res, int status, const std::string& type, const std::string& detail,
                  const std::string& field = {}) {
  ojson p = {{"type", type.find(':') == std::string::npos
                          ? "http://www.opengis.net/def/exceptions/ogcapi-processes-1/1.0/" + type
                          : type},
             {"title", status_title(status)},
             {"status", status},
             {"detail", detail}};
  if (!field.empty()) p["field"] = field;
  res.status = status;
  res.set_content(p.dump(2), "application/problem+json");
}

const char* content_type(const std::string& path) {
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".json") return "application/json";
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".glb") return "model/gltf-binary";
  if (ext == ".gltf") return "model/gltf+json";
  if (ext == ".obj") return "model/obj";
  if (ext == ".png") return "image/png";
  if (ext == ".csv") return "text/csv; charset=utf-8";
  if (ext == ".txt") return "text/plain; charset=utf-8";
  return "application/octet-stream";  // .ply, .b3dm, .subtree
}

// Whether `text` nests arrays and objects at most `max_depth` deep (strings skipped). nlohmann::json
// recurses on nesting, so a 1 MiB body of '[' would overflow the stack: such a body is refused first.
bool nesting_within(const std::string& text, int max_depth) {
  int depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max_depth) return false;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return true;
}

// A file name for an upload: letters, digits, '.', '_', '-', not starting with '.', with an extension.
bool safe_name(const std::string& s) {
  if (s.empty() || s.size() > 128 || s[0] == '.' || s.find('.') == std::string::npos) return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-')) return false;
  return true;
}

uint64_t half_of_ram() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page > 0 ? static_cast<uint64_t>(pages) * static_cast<uint64_t>(page) / 2 : 1ull << 30;
}

// The outputs of a successful job as links, by the output ids of its process description.
ojson results(const std::string& id, const std::string& out_dir) {
  const std::string base = "/jobs/" + id + "/files/";
  auto link = [&](const std::string& rel) { return ojson{{"href", base + rel}, {"type", content_type(rel)}}; };
  auto has = [&](const std::string& rel) { return fs::is_regular_file(out_dir + "/" + rel); };
  ojson r = ojson::object();
  if (has("manifest.json")) r["manifest"] = link("manifest.json");
  ojson levels = ojson::array();
  for (int l = 0; has("lod" + std::to_string(l) + ".ply"); ++l) levels.push_back(link("lod" + std::to_string(l) + ".ply"));
  if (!levels.empty()) r["levels"] = levels;
  ojson objs = ojson::array();
  for (int l = 0; has("lod" + std::to_string(l) + ".obj"); ++l) objs.push_back(link("lod" + std::to_string(l) + ".obj"));
  if (!objs.empty()) r["levels_obj"] = objs;
  if (has("lods.glb")) r["glb"] = link("lods.glb");
  if (has("tiles/tileset.json")) r["tiles"] = link("tiles/tileset.json");
  if (has("report.html")) r["report"] = link("report.html");
  if (has("report.json")) r["report_json"] = link("report.json");
  if (has("summary.json")) r["summary"] = link("summary.json");
  for (const char* g : {"glb", "ply", "obj"})
    if (has(std::string("grid.") + g)) r[g] = link(std::string("grid.") + g);
  ojson links = ojson::array();
  std::error_code ec;
  std::vector<std::string> files;
  for (auto it = fs::recursive_directory_iterator(out_dir, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
    if (it->is_regular_file()) files.push_back(fs::relative(it->path(), out_dir).string());
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    ojson l = link(f);
    l["rel"] = "item";
    l["title"] = f;
    links.push_back(l);
  }
  r["links"] = links;
  return r;
}

void serve_file(const httplib::Request& req, httplib::Response& res, const std::string& root, const std::string& rel) {
  const std::string path = resolve_under(root, rel);
  if (path.empty()) return send_problem(res, 404, "http://www.opengis.net/def/exceptions/ogcapi-processes-1/1.0/not-found",
                                        "no file '" + rel + "' in this job's outputs");
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  struct stat st {};
  if (fd < 0 || ::fstat(fd, &st) != 0) {
    if (fd >= 0) ::close(fd);
    return send_problem(res, 404, "not-found", "cannot open '" + rel + "'");
  }
  const size_t size = static_cast<size_t>(st.st_size);
  // Ranges past the end: 416 with the size, as RFC 9110 §15.5.17 asks (the library would send the whole).
  for (const auto& [first, last] : req.ranges)
    if (first >= 0 && static_cast<size_t>(first) >= size) {
      ::close(fd);
      res.set_header("Content-Range", "bytes */" + std::to_string(size));
      return send_problem(res, 416, "range-not-satisfiable", "the file has " + std::to_string(size) + " bytes");
    }
  auto file = std::shared_ptr<int>(new int(fd), [](int* f) {
    ::close(*f);
    delete f;
  });
  res.set_header("Accept-Ranges", "bytes");
  res.set_header("Cache-Control", "no-cache");
  res.set_content_provider(size, content_type(path), [file](size_t offset, size_t length, httplib::DataSink& sink) {
    char buf[65536];
    const size_t want = std::min(length, sizeof buf);
    const ssize_t n = ::pread(*file, buf, want, static_cast<off_t>(offset));
    if (n <= 0) return false;
    return sink.write(buf, static_cast<size_t>(n));
  });
}

}  // namespace

int run(const ServeOptions& o) {
  const size_t colon = o.bind.rfind(':');
  int port = -1;
  try {
    if (colon != std::string::npos) port = std::stoi(o.bind.substr(colon + 1));
  } catch (const std::exception&) {
  }
  if (colon == std::string::npos || port < 0 || port > 65535) {
    std::fprintf(stderr, "lodstream serve: --bind: expected HOST:PORT, got '%s'\n", o.bind.c_str());
    return 64;
  }
  std::string host = o.bind.substr(0, colon);
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  if (o.token_file.empty() && host != "127.0.0.1" && host != "localhost" && host != "::1")
    std::fprintf(stderr, "lodstream serve: warning: listening on %s without --token-file: anyone who reaches it can run jobs\n",
                 host.c_str());
  const std::string data_root = canonical(o.data_root);
  if (data_root.empty() || !fs::is_directory(data_root)) {
    std::fprintf(stderr, "lodstream serve: --data-root: '%s' is not a directory\n", o.data_root.c_str());
    return 66;
  }
  std::error_code ec;
  fs::create_directories(o.jobs_dir + "/uploads", ec);
  const std::string jobs_dir = canonical(o.jobs_dir);
  if (ec || jobs_dir.empty()) {
    std::fprintf(stderr, "lodstream serve: --jobs-dir: cannot create '%s'%s%s\n", o.jobs_dir.c_str(), ec ? ": " : "",
                 ec ? ec.message().c_str() : "");
    return 74;
  }
  const std::string uploads_dir = jobs_dir + "/uploads";
  std::string token;
  if (!o.token_file.empty()) {
    std::ifstream in(o.token_file);
    std::getline(in, token);
    while (!token.empty() && std::isspace(static_cast<unsigned char>(token.back()))) token.pop_back();
    if (!in && token.empty()) {
      std::fprintf(stderr, "lodstream serve: --token-file: cannot read '%s'\n", o.token_file.c_str());
      return 66;
    }
    if (token.size() < 16) {
      std::fprintf(stderr, "lodstream serve: --token-file: the token must have at least 16 characters\n");
      return 64;
    }
  }
  const uint64_t memory = o.memory_bytes ? o.memory_bytes : half_of_ram();
  if (memory < (64ull << 20) || o.max_jobs == 0) {
    std::fprintf(stderr, "lodstream serve: --memory must be at least 64M and --max-jobs at least 1\n");
    return 64;
  }

  // SIGTERM and SIGINT are taken by sigwait() below, in this thread only: blocked before any thread starts.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);

  std::string cli = o.cli;
  if (cli.empty()) {
    char self[4096];
    const ssize_t n = ::readlink("/proc/self/exe", self, sizeof self - 1);
    if (n <= 0) {
      std::fprintf(stderr, "lodstream serve: cannot find its own binary (/proc/self/exe)\n");
      return 70;
    }
    cli.assign(self, static_cast<size_t>(n));
  }
  JobManager jobs(jobs_dir, cli, o.max_jobs, memory);
  std::string error;
  if (!jobs.open(&error)) {
    std::fprintf(stderr, "lodstream serve: %s\n", error.c_str());
    return 74;
  }

  ConnectionLimits limits;
  limits.idle_seconds = o.timeout_seconds;
  limits.head_seconds = o.request_timeout_seconds;
  limits.min_rate = o.min_rate;
  // Connections are served by a pool of threads (cpp-httplib's default is 8): a client holds one until its
  // allowance runs out, so clients trickling bytes must open this many connections to make others wait.
  limits.threads = kConnectionThreads;
  GuardedServer svr(limits);
  svr.set_payload_max_length(std::max<size_t>(o.max_upload_bytes, kMaxJsonBody));
  svr.set_default_headers({{"X-Content-Type-Options", "nosniff"}, {"Referrer-Policy", "no-referrer"}});

  svr.set_pre_routing_handler([&](const httplib::Request& req, httplib::Response& res) {
    if (req.headers.size() > kMaxHeaders) {
      send_problem(res, 431, "request-header-fields-too-large", "at most " + std::to_string(kMaxHeaders) + " header fields");
      return httplib::Server::HandlerResponse::Handled;
    }
    if (!token.empty()) {
      const std::string auth = req.get_header_value("Authorization");
      const std::string given = auth.rfind("Bearer ", 0) == 0 ? auth.substr(7) : cookie_token(req);
      if (!same_token(given, token)) {
        res.set_header("WWW-Authenticate", "Bearer realm=\"lodstream\"");
        if (req.method == "GET" && wants_html(req)) {
          res.status = 401;
          res.set_content(login_page(), "text/html; charset=utf-8");
        } else {
          send_problem(res, 401, "unauthorized", "this server needs Authorization: Bearer <token>");
        }
        return httplib::Server::HandlerResponse::Handled;
      }
    }
    if (req.method == "POST" || req.method == "PUT" || req.method == "PATCH") {
      const bool upload = req.path == "/uploads";
      const size_t cap = upload ? o.max_upload_bytes : kMaxJsonBody;
      if (!req.has_header("Content-Length") && !upload) {
        send_problem(res, 411, "length-required", "a request body needs Content-Length");
        return httplib::Server::HandlerResponse::Handled;
      }
      if (req.has_header("Content-Length")) {
        const std::string len = req.get_header_value("Content-Length");
        uint64_t n = 0;
        if (len.empty() || len.size() > 19 || len.find_first_not_of("0123456789") != std::string::npos ||
            (n = std::stoull(len)) > cap) {
          send_problem(res, 413, "payload-too-large", "the body may have at most " + std::to_string(cap) + " bytes");
          return httplib::Server::HandlerResponse::Handled;
        }
      }
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });

  svr.Get("/", [&](const httplib::Request& req, httplib::Response& res) {
    if (wants_html(req)) {
      res.set_header("Content-Security-Policy",
                     "default-src 'self'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src 'self' data:");
      res.set_content(jobs_page(), "text/html; charset=utf-8");
      return;
    }
    send_json(res, 200,
              {{"title", "lodstream job server"},
               {"description", "Levels of detail, error reports and height-grid fits of huge scenes, as OGC API - Processes jobs"},
               {"links",
                {{{"href", "/"}, {"rel", "self"}, {"type", "application/json"}, {"title", "this document"}},
                 {{"href", "/?f=html"}, {"rel", "alternate"}, {"type", "text/html"}, {"title", "this page for people"}},
                 {{"href", "/conformance"},
                  {"rel", "http://www.opengis.net/def/rel/ogc/1.0/conformance"},
                  {"type", "application/json"},
                  {"title", "conformance classes"}},
                 {{"href", "/processes"},
                  {"rel", "http://www.opengis.net/def/rel/ogc/1.0/processes"},
                  {"type", "application/json"},
                  {"title", "processes"}},
                 {{"href", "/jobs"},
                  {"rel", "http://www.opengis.net/def/rel/ogc/1.0/job-list"},
                  {"type", "application/json"},
                  {"title", "jobs"}}}}});
  });

  svr.Get("/viewer", [&](const httplib::Request&, httplib::Response& res) {
    res.set_header("Content-Security-Policy", "default-src 'self'; script-src 'unsafe-inline'; style-src 'unsafe-inline'");
    res.set_content(viewer_page(), "text/html; charset=utf-8");
  });

  svr.Get("/conformance", [&](const httplib::Request&, httplib::Response& res) {
    const std::string base = "http://www.opengis.net/spec/ogcapi-processes-1/1.0/conf/";
    send_json(res, 200, {{"conformsTo", {base + "core", base + "ogc-process-description", base + "json", base + "html",
                                         base + "job-list", base + "dismiss"}}});
  });

  svr.Get("/processes", [&](const httplib::Request&, httplib::Response& res) {
    ojson list = ojson::array();
    for (const auto& id : process_ids()) {
      ojson s = *process_description(id);
      s.erase("inputs");
      s.erase("outputs");
      s["links"] = {{{"href", "/processes/" + id}, {"rel", "self"}, {"type", "application/json"}, {"title", "description"}}};
      list.push_back(s);
    }
    send_json(res, 200, {{"processes", list}, {"links", {{{"href", "/processes"}, {"rel", "self"}, {"type", "application/json"}}}}});
  });

  svr.Get(R"(/processes/([a-z]+))", [&](const httplib::Request& req, httplib::Response& res) {
    const ojson* d = process_description(req.matches[1]);
    if (!d) return send_problem(res, 404, "no-such-process", "no process named '" + std::string(req.matches[1]) + "'");
    send_json(res, 200, *d);
  });

  svr.Post(R"(/processes/([a-z]+)/execution)", [&](const httplib::Request& req, httplib::Response& res) {
    const std::string process = req.matches[1];
    if (!process_description(process)) return send_problem(res, 404, "no-such-process", "no process named '" + process + "'");
    if (!jobs.accepting()) return send_problem(res, 503, "service-unavailable", "the server is shutting down");
    if (!nesting_within(req.body, 32))
      return send_problem(res, 400, "invalid-parameter-value", "body: nested more than 32 levels deep", "body");
    nlohmann::json body;
    try {
      body = nlohmann::json::parse(req.body);
    } catch (const std::exception& e) {
      return send_problem(res, 400, "invalid-parameter-value", std::string("body: not JSON: ") + e.what(), "body");
    }
    const std::string id = jobs.new_id();
    PlanContext ctx{data_root, uploads_dir, jobs_dir, jobs.job_dir(id), memory, o.max_jobs, o.job_threads};
    JobPlan plan;
    PlanError perr;
    if (!plan_job(process, body, ctx, &plan, &perr))
      return send_problem(res, 400, "invalid-parameter-value", perr.detail, perr.field);
    std::error_code mk;
    fs::create_directories(ctx.job_dir, mk);
    std::string err;
    if (mk || !jobs.submit(id, process, body.value("inputs", nlohmann::json::object()), plan, &err)) {
      fs::remove_all(ctx.job_dir, mk);
      return send_problem(res, 503, "service-unavailable", err.empty() ? "cannot create the job's directory" : err);
    }
    ojson s;
    jobs.status(id, &s);
    res.set_header("Location", "/jobs/" + id);
    send_json(res, 201, s);
  });

  svr.Get("/jobs", [&](const httplib::Request&, httplib::Response& res) {
    send_json(res, 200, {{"jobs", jobs.list()}, {"links", {{{"href", "/jobs"}, {"rel", "self"}, {"type", "application/json"}}}}});
  });

  svr.Get(R"(/jobs/([^/]+))", [&](const httplib::Request& req, httplib::Response& res) {
    ojson s;
    if (!is_job_id(req.matches[1]) || !jobs.status(req.matches[1], &s))
      return send_problem(res, 404, "no-such-job", "no job '" + std::string(req.matches[1]) + "'");
    send_json(res, 200, s);
  });

  svr.Delete(R"(/jobs/([^/]+))", [&](const httplib::Request& req, httplib::Response& res) {
    ojson s;
    if (!is_job_id(req.matches[1]) || !jobs.dismiss(req.matches[1], &s))
      return send_problem(res, 404, "no-such-job", "no job '" + std::string(req.matches[1]) + "'");
    send_json(res, 200, s);
  });

  svr.Get(R"(/jobs/([^/]+)/results)", [&](const httplib::Request& req, httplib::Response& res) {
    const std::string id = req.matches[1];
    ojson s;
    if (!is_job_id(id) || !jobs.status(id, &s)) return send_problem(res, 404, "no-such-job", "no job '" + id + "'");
    const std::string out = jobs.output_dir(id);
    if (out.empty())
      return send_problem(res, 404, "result-not-ready",
                          "job " + id + " is " + s["status"].get<std::string>() + ": " + s["message"].get<std::string>());
    send_json(res, 200, results(id, out));
  });

  svr.Get(R"(/jobs/([^/]+)/files/(.+))", [&](const httplib::Request& req, httplib::Response& res) {
    const std::string id = req.matches[1];
    const std::string out = is_job_id(id) ? canonical(jobs.output_dir(id)) : std::string();
    if (out.empty()) return send_problem(res, 404, "no-such-job", "no successful job '" + id + "'");
    serve_file(req, res, out, req.matches[2]);
  });

  // An upload streams to disk under the jobs directory (never held in memory) and becomes a job input
  // named upload:<id>/<name>. The body is the file itself; ?name= gives its name (the format's extension).
  svr.Post("/uploads", [&](const httplib::Request& req, httplib::Response& res, const httplib::ContentReader& reader) {
    const std::string name = req.has_param("name") ? req.get_param_value("name") : std::string();
    if (!safe_name(name))
      return send_problem(res, 400, "invalid-parameter-value",
                          "name: give the file's name with its extension, letters, digits, '.', '_', '-' only", "name");
    if (req.is_multipart_form_data())
      return send_problem(res, 415, "unsupported-media-type", "send the file itself as the body, not a multipart form");
    const std::string id = jobs.new_id();
    const std::string dir = uploads_dir + "/" + id, tmp = dir + "/." + name + ".part";
    std::error_code mk;
    fs::create_directories(dir, mk);
    std::FILE* f = mk ? nullptr : std::fopen(tmp.c_str(), "wbe");
    if (!f) return send_problem(res, 507, "insufficient-storage", "cannot create the upload's file");
    uint64_t bytes = 0;
    bool too_large = false, write_failed = false;
    const bool read = reader([&](const char* data, size_t n) {
      bytes += n;
      if (bytes > o.max_upload_bytes) return !(too_large = true);
      if (std::fwrite(data, 1, n, f) != n) return !(write_failed = true);
      return true;
    });
    const bool closed = std::fclose(f) == 0;
    if (!read || too_large || write_failed || !closed) {
      fs::remove_all(dir, mk);
      if (too_large) return send_problem(res, 413, "payload-too-large", "an upload may have at most " + std::to_string(o.max_upload_bytes) + " bytes");
      return send_problem(res, write_failed || !closed ? 507 : 400, "upload-failed", "the upload did not complete");
    }
    fs::rename(tmp, dir + "/" + name, mk);
    if (mk) {
      fs::remove_all(dir, mk);
      return send_problem(res, 507, "insufficient-storage", "cannot keep the upload's file");
    }
    send_json(res, 201, {{"input", "upload:" + id + "/" + name}, {"bytes", bytes}});
  });

  svr.Delete(R"(/uploads/([^/]+))", [&](const httplib::Request& req, httplib::Response& res) {
    const std::string id = req.matches[1];
    std::error_code rm;
    if (!is_job_id(id) || !fs::is_directory(uploads_dir + "/" + id))
      return send_problem(res, 404, "not-found", "no upload '" + id + "'");
    fs::remove_all(uploads_dir + "/" + id, rm);
    res.status = 204;
  });

  svr.set_error_handler([&](const httplib::Request&, httplib::Response& res) {
    if (res.body.empty()) send_problem(res, res.status, "http-error", status_title(res.status));
  });
  svr.set_exception_handler([&](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
    std::string what = "internal error";
    try {
      std::rethrow_exception(ep);
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
    }
    send_problem(res, 500, "internal-error", what);
  });

  const int bound = port == 0 ? svr.bind_to_any_port(host) : (svr.bind_to_port(host, port) ? port : -1);
  if (bound < 0) {
    std::fprintf(stderr, "lodstream serve: cannot listen on %s\n", o.bind.c_str());
    return 74;
  }
  svr.widen_backlog(kListenBacklog);
  jobs.start();
  std::thread http([&] { svr.listen_after_bind(); });
  const bool v6 = host.find(':') != std::string::npos;
  std::printf("lodstream serve: listening on http://%s%s%s:%d/ (data %s, jobs %s, %u at once, %llu MiB)\n", v6 ? "[" : "",
              host.c_str(), v6 ? "]" : "", bound, data_root.c_str(), jobs_dir.c_str(), o.max_jobs,
              static_cast<unsigned long long>(memory >> 20));
  std::fflush(stdout);

  int sig = 0;
  sigwait(&stop_signals, &sig);
  std::printf("lodstream serve: %s: draining (running jobs stop at their next progress tick and resume at the next start)\n",
              sig == SIGTERM ? "SIGTERM" : "SIGINT");
  std::fflush(stdout);
  jobs.drain();
  svr.stop();
  http.join();
  std::printf("lodstream serve: drained, exiting\n");
  std::fflush(stdout);
  return 0;
}

}  // namespace lodstream::serve

// Process descriptions follow OGC API - Processes - Part 1: Core (OGC 18-062r2), §7.10 (process
// description) and §7.11 (execute): inputs and outputs each carry a JSON Schema. Validation covers the
// schema keywords these descriptions use (type, enum, minimum, maximum, exclusiveMinimum, minItems,
// maxItems, items, maxLength, pattern-free strings) and no others: a description never uses a keyword the
// validator would ignore.
#include "server/processes.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <initializer_list>
#include <map>

#include <sys/stat.h>

#include "lodstream/lodstream.h"

namespace lodstream::serve {
namespace {

namespace fs = std::filesystem;

ojson size_schema() {
  return {{"type", "string"}, {"maxLength", 32}, {"description", "A size such as 512M or 2G (binary multiples)"}};
}

ojson input(const char* title, ojson schema) { return {{"title", title}, {"schema", std::move(schema)}}; }

ojson enum_of(std::initializer_list<const char*> values, const char* fallback) {
  ojson e = ojson::array();
  for (const char* v : values) e.push_back(v);
  return {{"type", "string"}, {"enum", e}, {"default", fallback}};
}

ojson output(const char* title, const char* media_type, bool array = false) {
  ojson one = {{"type", "string"}, {"format", "uri"}, {"contentMediaType", media_type}};
  return {{"title", title}, {"schema", array ? ojson{{"type", "array"}, {"items", one}} : one}};
}

ojson describe(const char* id, const char* title, const char* description, ojson inputs, ojson outputs) {
  for (auto& [key, in] : inputs.items()) {
    in["minOccurs"] = key == "input" || key == "job" ? 1 : 0;
    in["maxOccurs"] = 1;
  }
  return {{"id", id},
          {"title", title},
          {"description", description},
          {"version", "0.1.0"},
          {"jobControlOptions", {"async-execute", "dismiss"}},
          {"outputTransmission", {"reference"}},
          {"inputs", std::move(inputs)},
          {"outputs", std::move(outputs)},
          {"links", ojson::array({{{"href", std::string("/processes/") + id + "/execution"},
                                   {"rel", "http://www.opengis.net/def/rel/ogc/1.0/execute"},
                                   {"title", "Execute endpoint"}}})}};
}

const std::map<std::string, ojson>& descriptions() {
  static const std::map<std::string, ojson> all = [] {
    std::map<std::string, ojson> m;
    const ojson scene = {{"type", "string"}, {"minLength", 1}, {"maxLength", 4096},
                         {"description", "A file under the server's data root (relative to it), or upload:<id>/<name> from POST /uploads"}};
    ojson si;
    si["input"] = input("Input scene (.obj, .ply, .stl, .glb, .gltf)", scene);
    si["levels"] = input("Exactly N levels when no sizes or targets are given", {{"type", "integer"}, {"minimum", 1}, {"maximum", 32}});
    si["cell_sizes"] = input("Cell sizes in scene units, finest first",
                             {{"type", "array"}, {"minItems", 1}, {"maxItems", 32}, {"items", {{"type", "number"}, {"exclusiveMinimum", 0}}}});
    si["target_triangles"] = input("Triangle counts to aim at (searched, within 15 %)",
                                   {{"type", "array"}, {"minItems", 1}, {"maxItems", 32}, {"items", {{"type", "integer"}, {"minimum", 1}}}});
    si["grading"] = input("Vertex grade", enum_of({"lowtan", "rossignac"}, "lowtan"));
    si["clustering"] = input("Clustering", enum_of({"floating", "uniform"}, "floating"));
    si["cell"] = input("Floating cell shape", enum_of({"cube", "sphere"}, "cube"));
    si["variant"] = input("Cell a vertex joins when several contain it", enum_of({"nearest", "heaviest"}, "nearest"));
    si["representative"] = input("Cell representative", enum_of({"center", "mean", "quadric"}, "quadric"));
    si["fov"] = input("Vertical field of view for switching distances, degrees",
                      {{"type", "number"}, {"exclusiveMinimum", 0}, {"maximum", 179}, {"default", 60}});
    si["resolution"] = input("Image height in pixels for switching distances", {{"type", "integer"}, {"minimum", 1}, {"maximum", 65536}, {"default", 1080}});
    si["pixels_per_cell"] = input("Cell width in pixels at the switch (Low & Tan's X)", {{"type", "number"}, {"exclusiveMinimum", 0}, {"default", 5}});
    si["obj"] = input("Also write lodN.obj", {{"type", "boolean"}, {"default", false}});
    si["tiles"] = input("Also write 3D Tiles 1.1 (tiles/tileset.json), which the job's viewer streams", {{"type", "boolean"}, {"default", false}});
    si["tiles_up"] = input("The input's up axis for tiles", enum_of({"y", "z"}, "y"));
    si["tile_triangles"] = input("Triangles a tile (and an emit region) holds, about", {{"type", "integer"}, {"minimum", 2}, {"default", 200000}});
    si["report"] = input("Then measure each level's error in pixels (lodstream report: report.html)", {{"type", "boolean"}, {"default", true}});
    si["views"] = input("Report: view directions per level", {{"type", "integer"}, {"minimum", 1}, {"maximum", 1024}, {"default", 32}});
    si["samples"] = input("Report: Hausdorff samples of each kind per direction", {{"type", "integer"}, {"minimum", 1}, {"maximum", 100000000}});
    si["memory"] = input("Cap on the job's peak resident memory", size_schema());
    ojson so;
    so["manifest"] = output("manifest.json: levels, cell sizes, counts, switching distances", "application/json");
    so["levels"] = output("One PLY file per level, finest first", "application/octet-stream", true);
    so["glb"] = output("lods.glb: every level in one glTF binary (MSFT_lod)", "model/gltf-binary");
    so["tiles"] = output("3D Tiles 1.1 tileset.json (when the job wrote tiles)", "application/json");
    so["report"] = output("report.html (when the job ran the report)", "text/html");
    m["simplify"] = describe("simplify", "Levels of detail by vertex clustering (Low & Tan 1997)",
                             "Builds a chain of levels of detail out of core: lodstream simplify.", si, so);

    ojson ri;
    ri["job"] = input("A successful simplify job whose levels are measured",
                      {{"type", "string"}, {"minLength", 32}, {"maxLength", 32}, {"description", "The job id (32 hex digits)"}});
    ri["views"] = input("View directions per level", {{"type", "integer"}, {"minimum", 1}, {"maximum", 1024}, {"default", 32}});
    ri["resolution"] = input("Image width and height in pixels", {{"type", "integer"}, {"minimum", 16}, {"maximum", 8192}, {"default", 512}});
    ri["samples"] = input("Hausdorff samples of each kind per direction", {{"type", "integer"}, {"minimum", 1}, {"maximum", 100000000}});
    ri["seed"] = input("Seed of view targets and surface samples", {{"type", "integer"}, {"minimum", 0}, {"maximum", 4294967295LL}});
    ri["memory"] = input("Cap on the job's peak resident memory", size_schema());
    ojson ro;
    ro["report"] = output("report.html: renders, heat maps, error against triangles", "text/html");
    ro["report_json"] = output("report.json: the figures", "application/json");
    m["report"] = describe("report", "Error of each level in pixels at its switching distance",
                           "Ray casts original and levels with Embree and measures silhouette, depth, normal and Hausdorff "
                           "error: lodstream report.", ri, ro);

    ojson gi;
    gi["input"] = input("Height grid (Terrain-RGB PNG, PGM, ESRI ASCII .asc)", scene);
    gi["tolerance"] = input("Largest vertical distance of a sample from the drawn surface", {{"type", "number"}, {"minimum", 0}});
    gi["split"] = input("Where a failing polygon splits", enum_of({"center", "first", "greatest", "curvature", "random"}, "greatest"));
    gi["divide"] = input("Split into 4, or 2 across the longer side", {{"type", "integer"}, {"enum", {2, 4}}, {"default", 4}});
    gi["gaps"] = input("Edge gaps", enum_of({"none", "extra-vertices", "fill"}, "extra-vertices"));
    gi["target_polygons"] = input("Refine greatest error first until N polygons", {{"type", "integer"}, {"minimum", 1}});
    gi["method"] = input("Algorithm", enum_of({"subdivision", "growth"}, "subdivision"));
    gi["merge"] = input("Merge polygons sharing a whole side while their union passes", {{"type", "boolean"}, {"default", false}});
    gi["z_scale"] = input("PGM: height = sample value times this", {{"type", "number"}});
    gi["spacing"] = input("Sample distance, overriding the file's", {{"type", "number"}, {"exclusiveMinimum", 0}});
    gi["cylindrical"] = input("The grid holds a cylindrical scan's radii", {{"type", "boolean"}, {"default", false}});
    gi["memory"] = input("Cap on the job's peak resident memory", size_schema());
    ojson go;
    go["summary"] = output("summary.json", "application/json");
    go["glb"] = output("grid.glb", "model/gltf-binary");
    go["ply"] = output("grid.ply", "application/octet-stream");
    go["obj"] = output("grid.obj", "model/obj");
    m["grid"] = describe("grid", "Adaptive subdivision of a height grid (DeHaemer 1989)",
                         "Fits polygons to a height grid within a tolerance: lodstream grid.", gi, go);
    return m;
  }();
  return all;
}

// Checks `value` against `schema` (the subset the descriptions use); `field` names it in the error.
bool check(const nlohmann::json& value, const ojson& schema, const std::string& field, PlanError* error) {
  auto fail = [&](const std::string& what) {
    *error = {field, field + ": " + what};
    return false;
  };
  const std::string type = schema.value("type", "");
  if (type == "string" && !value.is_string()) return fail("must be a string");
  if (type == "boolean" && !value.is_boolean()) return fail("must be true or false");
  if (type == "integer" && !value.is_number_integer()) return fail("must be an integer");
  if (type == "number" && !value.is_number()) return fail("must be a number");
  if (type == "array" && !value.is_array()) return fail("must be an array");
  if (schema.contains("enum")) {
    bool found = false;
    for (const auto& e : schema["enum"]) found = found || nlohmann::json(e) == value;
    if (!found) return fail("must be one of " + schema["enum"].dump());
  }
  if (value.is_number()) {
    const double v = value.get<double>();
    if (!std::isfinite(v)) return fail("must be finite");
    if (schema.contains("minimum") && v < schema["minimum"].get<double>()) return fail("must be at least " + schema["minimum"].dump());
    if (schema.contains("maximum") && v > schema["maximum"].get<double>()) return fail("must be at most " + schema["maximum"].dump());
    if (schema.contains("exclusiveMinimum") && !(v > schema["exclusiveMinimum"].get<double>()))
      return fail("must be greater than " + schema["exclusiveMinimum"].dump());
  }
  if (value.is_string()) {
    const size_t n = value.get_ref<const std::string&>().size();
    if (schema.contains("minLength") && n < schema["minLength"].get<size_t>()) return fail("is too short");
    if (schema.contains("maxLength") && n > schema["maxLength"].get<size_t>()) return fail("is too long");
  }
  if (value.is_array()) {
    if (schema.contains("minItems") && value.size() < schema["minItems"].get<size_t>()) return fail("has too few items");
    if (schema.contains("maxItems") && value.size() > schema["maxItems"].get<size_t>()) return fail("has too many items");
    if (schema.contains("items"))
      for (size_t i = 0; i < value.size(); ++i)
        if (!check(value[i], schema["items"], field + "[" + std::to_string(i) + "]", error)) return false;
  }
  return true;
}

std::string string_text(const nlohmann::json& v) { return v.get<std::string>(); }

std::string number_text(const nlohmann::json& v) {
  // A JSON number's own shortest text, so that the child reads back exactly the value sent.
  return v.dump();
}

std::string list_text(const nlohmann::json& a) {
  std::string s;
  for (const auto& v : a) {
    if (!s.empty()) s += ',';
    s += number_text(v);
  }
  return s;
}

}  // namespace

const ojson* process_description(const std::string& id) {
  const auto& all = descriptions();
  const auto it = all.find(id);
  return it == all.end() ? nullptr : &it->second;
}

const std::vector<std::string>& process_ids() {
  static const std::vector<std::string> ids = {"simplify", "report", "grid"};
  return ids;
}

bool is_job_id(const std::string& s) {
  if (s.size() != 32) return false;
  for (char c : s)
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  return true;
}

std::string canonical(const std::string& path) {
  char* r = ::realpath(path.c_str(), nullptr);
  if (!r) return {};
  std::string s(r);
  std::free(r);
  return s;
}

std::string resolve_under(const std::string& root, const std::string& path) {
  if (path.empty() || path.find('\0') != std::string::npos) return {};
  const fs::path joined = fs::path(path).is_absolute() ? fs::path(path) : fs::path(root) / path;
  const std::string r = canonical(joined.string());
  if (r.size() <= root.size() || r.compare(0, root.size(), root) != 0 || r[root.size()] != '/') return {};
  struct stat st {};
  if (::stat(r.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return {};
  return r;
}

bool plan_job(const std::string& process, const nlohmann::json& body, const PlanContext& ctx, JobPlan* plan,
              PlanError* error) {
  const ojson* desc = process_description(process);
  if (!desc) {
    *error = {"", "no process named '" + process + "'"};
    return false;
  }
  if (!body.is_object()) {
    *error = {"", "the request body must be a JSON object {\"inputs\": {...}}"};
    return false;
  }
  for (const auto& [key, value] : body.items())
    if (key != "inputs" && key != "outputs" && key != "response" && key != "subscriber") {
      *error = {key, key + ": not a member of an execute request (inputs, outputs, response, subscriber)"};
      return false;
    }
  if (body.contains("response") && body["response"] != "document") {
    *error = {"response", "response: only \"document\" is offered (outputs are links)"};
    return false;
  }
  const nlohmann::json inputs = body.value("inputs", nlohmann::json::object());
  if (!inputs.is_object()) {
    *error = {"inputs", "inputs: must be an object"};
    return false;
  }
  const ojson& schema = (*desc)["inputs"];
  for (const auto& [key, value] : inputs.items()) {
    if (!schema.contains(key)) {
      *error = {"inputs." + key, "inputs." + key + ": no such input of process " + process};
      return false;
    }
    if (!check(value, schema[key]["schema"], "inputs." + key, error)) return false;
  }
  const char* required = process == "report" ? "job" : "input";
  if (!inputs.contains(required)) {
    *error = {std::string("inputs.") + required, std::string("inputs.") + required + ": required"};
    return false;
  }

  // Memory: the job's own cap, or an equal share of the server's.
  uint64_t memory = std::max<uint64_t>(64ull << 20, ctx.server_memory / std::max(1u, ctx.max_jobs));
  if (inputs.contains("memory") && !lodstream::parse_size(inputs["memory"].get<std::string>(), &memory)) {
    *error = {"inputs.memory", "inputs.memory: cannot read '" + inputs["memory"].get<std::string>() + "' as a size (e.g. 512M)"};
    return false;
  }
  if (memory < (64ull << 20) || memory > ctx.server_memory) {
    *error = {"inputs.memory", "inputs.memory: must be between 64M and the server's --memory (" +
                                   std::to_string(ctx.server_memory >> 20) + "M)"};
    return false;
  }
  plan->memory_bytes = memory;

  auto scene_path = [&](std::string* out) {
    const std::string& in = inputs["input"].get_ref<const std::string&>();
    static const std::string prefix = "upload:";
    if (in.compare(0, prefix.size(), prefix) == 0) *out = resolve_under(ctx.uploads_dir, in.substr(prefix.size()));
    else *out = resolve_under(ctx.data_root, in);
    if (out->empty()) *error = {"inputs.input", "inputs.input: '" + in + "' is not a file under the data root (or an upload)"};
    return !out->empty();
  };
  const std::string out_dir = ctx.job_dir + "/out", work = ctx.job_dir + "/work";
  std::vector<std::string> common = {"--memory", std::to_string(memory), "--threads", std::to_string(ctx.job_threads),
                                     "--progress", "json"};
  auto add_step = [&](std::vector<std::string> argv, const std::string& step) {
    argv.insert(argv.end(), common.begin(), common.end());
    argv.push_back("--work");
    argv.push_back(work + "/" + step);
    plan->steps.push_back(std::move(argv));
    plan->step_names.push_back(step);
  };
  // Each given input as "--<name with '-' for '_'> <text>", in the order listed.
  auto pass = [&](std::vector<std::string>& argv, std::initializer_list<const char*> names,
                  std::string (*text)(const nlohmann::json&)) {
    for (const char* name : names)
      if (inputs.contains(name)) {
        std::string flag = std::string("--") + name;
        std::replace(flag.begin(), flag.end(), '_', '-');
        argv.insert(argv.end(), {flag, text(inputs[name])});
      }
  };

  if (process == "simplify") {
    std::string path;
    if (!scene_path(&path)) return false;
    std::vector<std::string> a = {"simplify", path, "-o", out_dir};
    pass(a, {"grading", "clustering", "cell", "variant", "representative"}, string_text);
    pass(a, {"levels"}, number_text);
    pass(a, {"cell_sizes", "target_triangles"}, list_text);
    pass(a, {"fov", "resolution", "pixels_per_cell"}, number_text);
    if (inputs.value("obj", false)) a.push_back("--obj");
    // Float tiles: the job's viewer (server/page.cpp) parses GLBs itself and reads neither
    // KHR_mesh_quantization nor EXT_meshopt_compression.
    if (inputs.value("tiles", false)) a.insert(a.end(), {"--tiles", "--tile-encoding", "plain"});
    pass(a, {"tiles_up"}, string_text);
    pass(a, {"tile_triangles"}, number_text);
    add_step(a, "simplify");
    if (inputs.value("report", true)) {
      std::vector<std::string> r = {"report", out_dir};
      pass(r, {"views", "samples"}, number_text);
      add_step(r, "report");
    }
    return true;
  }
  if (process == "report") {
    const std::string job = inputs["job"].get<std::string>();
    const std::string manifest = is_job_id(job) ? resolve_under(ctx.jobs_dir, job + "/out/manifest.json") : std::string();
    if (manifest.empty()) {
      *error = {"inputs.job", "inputs.job: no successful simplify job '" + job + "'"};
      return false;
    }
    std::vector<std::string> r = {"report", ctx.jobs_dir + "/" + job + "/out", "-o", out_dir};
    pass(r, {"views", "resolution", "samples", "seed"}, number_text);
    add_step(r, "report");
    return true;
  }
  std::string path;
  if (!scene_path(&path)) return false;
  std::vector<std::string> g = {"grid", path, "-o", out_dir};
  pass(g, {"split", "gaps", "method"}, string_text);
  pass(g, {"tolerance", "divide", "target_polygons", "z_scale", "spacing"}, number_text);
  if (inputs.value("merge", false)) g.push_back("--merge");
  if (inputs.value("cylindrical", false)) g.push_back("--cylindrical");
  add_step(g, "grid");
  return true;
}

}  // namespace lodstream::serve

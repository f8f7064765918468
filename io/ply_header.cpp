#include "io/ply_header.h"

#include <algorithm>
#include <charconv>
#include <cstring>
#include <string>
#include <system_error>
#include <utility>

#include "io/reader.h"
#include "io/text.h"

namespace lodstream::io::ply {
namespace {

bool has_binary_bytes(const char* p, const char* end) {
  for (; p < end; ++p)
    if (!text::is_text_byte(static_cast<unsigned char>(*p))) return true;
  return false;
}

// The binary layout of an element's records: offsets of the scalars of fixed-size records, the smallest size.
void layout(Element& e) {
  uint64_t offset = 0, min_size = 0;
  for (Property& pr : e.props) {
    pr.offset = static_cast<uint32_t>(offset);
    if (pr.list) {
      e.fixed = false;
      min_size += type_size(pr.count_type);
    } else {
      min_size += type_size(pr.type);
      offset += type_size(pr.type);
    }
  }
  e.min_size = min_size;
}

}  // namespace

const char* format_name(Format f) {
  switch (f) {
    case Format::ascii: return "ply-ascii";
    case Format::le: return "ply-binary-le";
    case Format::be: return "ply-binary-be";
  }
  return "ply";
}

std::string quoted(std::string_view s) {
  std::string r = "'";
  for (size_t i = 0; i < s.size() && i < 40; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    r += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  if (s.size() > 40) r += "...";
  return r + "'";
}

bool parse_header(const MappedFile& file, std::string_view head, bool at_eof, Header* out,
                  MissingEndLine missing_end) {
  auto header_error = [&](uint64_t line, const std::string& message) { fail_at_line(file, line, message); };
  *out = Header{};
  std::vector<Element>& elements = out->elements;
  bool saw_format = false;
  const char* const base = head.data();
  const char* const end = base + head.size();
  const char* p = base;
  uint64_t line = 0;
  bool last_unterminated = false;
  while (p < end) {
    const char* nl = static_cast<const char*>(std::memchr(p, '\n', static_cast<size_t>(end - p)));
    if (!nl && !at_eof) {
      // Read more of the file for this line, unless it is already binary (a missing end_header).
      if (has_binary_bytes(p, end)) header_error(line + 1, "binary data in the PLY header (is end_header missing?)");
      return false;
    }
    const char* le = nl ? nl : end;
    last_unterminated = !nl;
    ++line;
    const char* lp = p;
    p = nl ? nl + 1 : end;
    const std::string_view whole(lp, static_cast<size_t>(le - lp));
    if (has_binary_bytes(lp, le))
      header_error(line, "binary data in the PLY header (is end_header missing?): " + quoted(whole));
    const std::string_view keyword = text::next_token(lp, le);
    auto expect_end = [&](const char* what) {
      const std::string_view extra = text::next_token(lp, le);
      if (!extra.empty()) header_error(line, std::string("unexpected ") + quoted(extra) + " after " + what);
    };
    if (line == 1) {
      if (keyword != "ply") header_error(line, "not a PLY file: the first line must be 'ply'");
      expect_end("'ply'");
      continue;
    }
    if (keyword.empty()) continue;  // tolerate blank header lines
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "format") {
      if (saw_format) header_error(line, "second format line");
      const std::string_view f = text::next_token(lp, le);
      const std::string_view version = text::next_token(lp, le);
      if (f == "ascii") out->format = Format::ascii;
      else if (f == "binary_little_endian") out->format = Format::le;
      else if (f == "binary_big_endian") out->format = Format::be;
      else
        header_error(line, "unknown PLY format " + quoted(f) +
                               " (expected ascii, binary_little_endian or binary_big_endian)");
      if (version != "1.0") header_error(line, "unsupported PLY version " + quoted(version) + " (expected 1.0)");
      expect_end("the format line");
      saw_format = true;
      continue;
    }
    if (keyword == "element") {
      if (!saw_format) header_error(line, "element before the format line");
      const std::string_view name = text::next_token(lp, le);
      const std::string_view count = text::next_token(lp, le);
      if (name.empty() || count.empty()) header_error(line, "bad element line: expected 'element NAME COUNT'");
      uint64_t n = 0;
      const auto [q, ec] = std::from_chars(count.data(), count.data() + count.size(), n);
      if (ec != std::errc() || q != count.data() + count.size())
        header_error(line, "bad element count " + quoted(count) + " for element " + quoted(name));
      expect_end("the element line");
      for (const Element& e : elements)
        if (e.name == name) header_error(line, "second element named " + quoted(name));
      Element e;
      e.name = std::string(name);
      e.count = n;
      e.header_line = line;
      elements.push_back(std::move(e));
      continue;
    }
    if (keyword == "property") {
      if (elements.empty()) header_error(line, "property before any element");
      Property pr;
      std::string_view t = text::next_token(lp, le);
      if (t == "list") {
        pr.list = true;
        const std::string_view ct = text::next_token(lp, le);
        if (ct.empty()) header_error(line, "bad list property: expected 'property list COUNTTYPE ITEMTYPE NAME'");
        pr.count_type = type_from_name(ct);
        if (pr.count_type == Type::none) header_error(line, "unknown property type " + quoted(ct));
        if (!is_integer(pr.count_type))
          header_error(line, "list count type must be an integer type, not " + quoted(ct));
        t = text::next_token(lp, le);
      }
      if (t.empty()) header_error(line, "bad property line: expected 'property TYPE NAME'");
      pr.type = type_from_name(t);
      if (pr.type == Type::none) header_error(line, "unknown property type " + quoted(t));
      const std::string_view name = text::next_token(lp, le);
      if (name.empty()) header_error(line, "property without a name");
      expect_end("the property line");
      Element& e = elements.back();
      for (const Property& other : e.props)
        if (other.name == name)
          header_error(line, "second property named " + quoted(name) + " in element " + quoted(e.name));
      pr.name = std::string(name);
      e.props.push_back(std::move(pr));
      continue;
    }
    if (keyword == "end_header") {
      expect_end("end_header");
      if (!saw_format) header_error(line, "no format line before end_header");
      out->data_start = static_cast<uint64_t>(p - base);
      out->lines = line;
      for (Element& e : elements) layout(e);
      return true;
    }
    header_error(line, "unknown PLY header line " + quoted(whole));
  }
  if (!at_eof) return false;
  const bool next_line = missing_end == MissingEndLine::after_last || !last_unterminated;
  header_error(line + (next_line ? 1 : 0), "the PLY header has no end_header line");
  return false;  // not reached
}

void count_error(const MappedFile& file, const Header& header, const Element& e, uint64_t per, uint64_t used) {
  const uint64_t avail = file.size() - header.data_start;
  fail_at_line(file, e.header_line,
               "element " + quoted(e.name) + " declares " + std::to_string(e.count) + " records of at least " +
                   std::to_string(per) + " bytes each, but only " + std::to_string(avail - std::min(avail, used)) +
                   " bytes of data remain for it (from byte " +
                   std::to_string(header.data_start + std::min(avail, used)) +
                   "): the file is truncated or the count is wrong");
}

}  // namespace lodstream::io::ply

#include "clients/cli/stage_flags.h"

#include <charconv>
#include <cstdlib>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"

namespace instascene::cli {
namespace {

std::string HelpText(const pipeline::ParamSpec& p) {
  std::string help = p.help;
  absl::StrAppend(&help, " (default ", p.default_value.dump());
  if (p.type == pipeline::ParamType::kInt || p.type == pipeline::ParamType::kDouble)
    absl::StrAppend(&help, ", range [", p.min, ", ", p.max, "]");
  if (!p.choices.empty()) {
    absl::StrAppend(&help, ", one of");
    for (const std::string& c : p.choices) absl::StrAppend(&help, " ", c);
  }
  absl::StrAppend(&help, ")");
  return help;
}

}  // namespace

void StageFlags::Add(CLI::App* cmd, const pipeline::StageSpec& spec) {
  for (const pipeline::ParamSpec& p : spec.parameters) {
    if (flags_.count(p.name))
      throw std::logic_error(absl::StrCat("parameter ", p.name, " of stage ", spec.kind,
                                          " is already a flag of this command"));
    Flag& f = flags_[p.name];
    f.kind = spec.kind;
    f.spec = p;
    f.flag = "--" + absl::StrReplaceAll(p.name, {{"_", "-"}});
    if (p.type == pipeline::ParamType::kBool && p.default_value == false) {
      f.option = cmd->add_flag(f.flag, f.set, HelpText(p));
    } else {
      f.option = cmd->add_option(f.flag, f.text, HelpText(p));
      static constexpr const char* kTypeNames[] = {"BOOL", "INT", "FLOAT", "TEXT"};
      f.option->type_name(kTypeNames[static_cast<int>(p.type)]);
      if (!p.choices.empty()) f.option->check(CLI::IsMember(p.choices));
    }
  }
}

absl::StatusOr<nlohmann::json> StageFlags::Parameters() const {
  nlohmann::json out = nlohmann::json::object();
  for (const auto& [name, f] : flags_) {
    if (f.option->count() == 0) continue;
    const std::string& t = f.text;
    auto bad = [&](const char* want) {
      return absl::InvalidArgumentError(absl::StrCat(f.flag, " ", t, ": not ", want));
    };
    nlohmann::json value;
    switch (f.spec.type) {
      case pipeline::ParamType::kBool:
        if (f.spec.default_value == false) {
          value = f.set;
        } else if (t == "true" || t == "false") {
          value = t == "true";
        } else {
          return bad("true or false");
        }
        break;
      case pipeline::ParamType::kInt: {
        int64_t v = 0;
        const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
        if (ec != std::errc() || end != t.data() + t.size() || t.empty()) return bad("an integer");
        value = v;
        break;
      }
      case pipeline::ParamType::kDouble: {
        char* end = nullptr;
        const double v = std::strtod(t.c_str(), &end);
        if (t.empty() || end != t.c_str() + t.size()) return bad("a number");
        value = v;
        break;
      }
      case pipeline::ParamType::kString:
        value = t;
        break;
    }
    out[f.kind][name] = value;
  }
  return out;
}

}  // namespace instascene::cli

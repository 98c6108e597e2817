// services/pipeline/params.h: the one parameter codec of a stage. A codec binds JSON keys to the
// fields of the stage's Options struct with their type, bounds and help text; the defaults are
// the struct's own. The same codec decodes a job's parameters in the scheduler (at submission) and
// in the worker, and generates the CLI's flags (clients/cli/stage_flags.h), so a flag exists on the
// command line exactly when the service accepts the parameter, with the same default and bounds.
// Decoding refuses unknown keys, wrong types and out-of-range values with InvalidArgument naming
// the stage and the key. Header-only; codecs are immutable after construction and thread-safe.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

namespace instascene::pipeline {

enum class ParamType { kBool, kInt, kDouble, kString };

// One parameter as clients see it (CLI flags, docs, the web UI's forms).
struct ParamSpec {
  std::string name;  // JSON key; the CLI flag is --name with '_' -> '-'
  ParamType type = ParamType::kInt;
  nlohmann::json default_value;
  double min = -std::numeric_limits<double>::infinity();  // inclusive bounds of numbers
  double max = std::numeric_limits<double>::infinity();
  std::vector<std::string> choices;  // strings: the allowed values
  std::string help;
};

// JSON -> Options -> canonical JSON, with a schema.
template <typename O>
class ParamCodec {
 public:
  explicit ParamCodec(std::string stage) : stage_(std::move(stage)) {}

  ParamCodec& Bool(const char* name, bool O::*field, const char* help) {
    ParamSpec spec{name, ParamType::kBool, Defaults().*field, 0, 1, {}, help};
    return Add(
        std::move(spec), [field](const nlohmann::json& v, O* o) { o->*field = v.get<bool>(); },
        [field](const O& o) { return nlohmann::json(o.*field); });
  }
  template <typename I>
  ParamCodec& Int(const char* name, I O::*field, int64_t min, int64_t max, const char* help) {
    static_assert(std::is_integral_v<I>);
    ParamSpec spec{name,
                   ParamType::kInt,
                   Defaults().*field,
                   static_cast<double>(min),
                   static_cast<double>(max),
                   {},
                   help};
    return Add(
        std::move(spec),
        [field](const nlohmann::json& v, O* o) { o->*field = static_cast<I>(v.get<int64_t>()); },
        [field](const O& o) { return nlohmann::json(o.*field); });
  }
  template <typename F>
  ParamCodec& Real(const char* name, F O::*field, double min, double max, const char* help) {
    static_assert(std::is_floating_point_v<F>);
    ParamSpec spec{name, ParamType::kDouble, static_cast<double>(Defaults().*field), min, max, {},
                   help};
    return Add(
        std::move(spec),
        [field](const nlohmann::json& v, O* o) { o->*field = static_cast<F>(v.get<double>()); },
        [field](const O& o) { return nlohmann::json(static_cast<double>(o.*field)); });
  }
  ParamCodec& Choice(const char* name, std::string O::*field, std::vector<std::string> choices,
                     const char* help) {
    ParamSpec spec{name, ParamType::kString, Defaults().*field, 0, 0, std::move(choices), help};
    return Add(
        std::move(spec),
        [field](const nlohmann::json& v, O* o) { o->*field = v.get<std::string>(); },
        [field](const O& o) { return nlohmann::json(o.*field); });
  }
  // An enum field named by strings.
  template <typename E>
  ParamCodec& Enum(const char* name, E O::*field, std::vector<std::pair<std::string, E>> names,
                   const char* help) {
    std::vector<std::string> choices;
    std::string default_name;
    for (const auto& [n, e] : names) {
      choices.push_back(n);
      if (e == Defaults().*field) default_name = n;
    }
    ParamSpec spec{name, ParamType::kString, default_name, 0, 0, choices, help};
    return Add(
        std::move(spec),
        [field, names](const nlohmann::json& v, O* o) {
          for (const auto& [n, e] : names)
            if (n == v.get<std::string>()) o->*field = e;
        },
        [field, names](const O& o) {
          for (const auto& [n, e] : names)
            if (e == o.*field) return nlohmann::json(n);
          return nlohmann::json();
        });
  }
  // A check across fields after decoding (e.g. Options::Validate).
  ParamCodec& Check(std::function<absl::Status(const O&)> check) {
    checks_.push_back(std::move(check));
    return *this;
  }

  absl::StatusOr<O> Decode(const nlohmann::json& parameters) const {
    if (!parameters.is_object())
      return Bad(absl::StrCat("parameters must be a JSON object, not ", parameters.dump()));
    O o = Defaults();
    for (const auto& [key, value] : parameters.items()) {
      const Field* f = FindField(key);
      if (f == nullptr) {
        std::vector<std::string> known;
        for (const Field& k : fields_) known.push_back(k.spec.name);
        return Bad(absl::StrCat("unknown parameter '", key, "' (known: ",
                                known.empty() ? "none" : absl::StrJoin(known, ", "), ")"));
      }
      if (absl::Status s = CheckValue(f->spec, value); !s.ok()) return s;
      f->read(value, &o);
    }
    for (const auto& check : checks_) {
      if (absl::Status s = check(o); !s.ok()) return Bad(std::string(s.message()));
    }
    return o;
  }
  // Every parameter, defaults filled in: equal options give equal JSON (job keys).
  nlohmann::json Encode(const O& o) const {
    nlohmann::json j = nlohmann::json::object();
    for (const Field& f : fields_) j[f.spec.name] = f.write(o);
    return j;
  }
  absl::StatusOr<nlohmann::json> Canonicalize(const nlohmann::json& parameters) const {
    absl::StatusOr<O> o = Decode(parameters);
    if (!o.ok()) return o.status();
    return Encode(*o);
  }
  std::vector<ParamSpec> Schema() const {
    std::vector<ParamSpec> specs;
    for (const Field& f : fields_) specs.push_back(f.spec);
    return specs;
  }
  const std::string& stage() const { return stage_; }

 private:
  struct Field {
    ParamSpec spec;
    std::function<void(const nlohmann::json&, O*)> read;
    std::function<nlohmann::json(const O&)> write;
  };
  static const O& Defaults() {
    static const O defaults{};
    return defaults;
  }
  ParamCodec& Add(ParamSpec spec, std::function<void(const nlohmann::json&, O*)> read,
                  std::function<nlohmann::json(const O&)> write) {
    fields_.push_back({std::move(spec), std::move(read), std::move(write)});
    return *this;
  }
  const Field* FindField(const std::string& name) const {
    for (const Field& f : fields_)
      if (f.spec.name == name) return &f;
    return nullptr;
  }
  absl::Status Bad(const std::string& why) const {
    return absl::InvalidArgumentError(absl::StrCat("stage ", stage_, ": ", why));
  }
  absl::Status CheckValue(const ParamSpec& spec, const nlohmann::json& v) const {
    auto wrong = [&](const char* want) {
      return Bad(absl::StrCat("parameter '", spec.name, "' must be ", want, ", not ", v.dump()));
    };
    auto range = [&](double x) -> absl::Status {
      if (x >= spec.min && x <= spec.max) return absl::OkStatus();
      return Bad(absl::StrCat("parameter '", spec.name, "' = ", v.dump(), " is outside [", spec.min,
                              ", ", spec.max, "]"));
    };
    switch (spec.type) {
      case ParamType::kBool:
        return v.is_boolean() ? absl::OkStatus() : wrong("true or false");
      case ParamType::kInt:
        if (!v.is_number_integer()) return wrong("an integer");
        if (v.is_number_unsigned() && v.get<uint64_t>() > uint64_t{1} << 62)
          return range(static_cast<double>(v.get<uint64_t>()));
        return range(static_cast<double>(v.get<int64_t>()));
      case ParamType::kDouble:
        if (!v.is_number()) return wrong("a number");
        return range(v.get<double>());
      case ParamType::kString: {
        if (!v.is_string()) return wrong("a string");
        for (const std::string& c : spec.choices)
          if (c == v.get<std::string>()) return absl::OkStatus();
        return Bad(absl::StrCat("parameter '", spec.name, "' = ", v.dump(), " is not one of ",
                                absl::StrJoin(spec.choices, ", ")));
      }
    }
    return absl::OkStatus();
  }

  std::string stage_;
  std::vector<Field> fields_;
  std::vector<std::function<absl::Status(const O&)>> checks_;
};

}  // namespace instascene::pipeline

#include "wire/map_settings_text.h"

#include <cctype>
#include <charconv>
#include <cstdio>
#include <cstdlib>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/reflection.h>

namespace recog {
namespace {

namespace gp = ::google::protobuf;
using ::recognition::v1::MapSettings;

// "GeometryCheck" -> "GEOMETRY_CHECK_": the prefix of every value of a proto enum (style guide).
std::string EnumValuePrefix(const gp::EnumDescriptor& type) {
  std::string prefix;
  for (const char c : type.name()) {
    if (std::isupper(static_cast<unsigned char>(c)) && !prefix.empty()) prefix += '_';
    prefix += char(std::toupper(static_cast<unsigned char>(c)));
  }
  return prefix + "_";
}

std::string EnumText(const gp::EnumValueDescriptor& value) {
  std::string text = value.name().substr(EnumValuePrefix(*value.type()).size());
  for (char& c : text) c = char(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

// The field `name` if it is one that text stands for: a singular number, string or enum.
const gp::FieldDescriptor* Field(std::string_view name) {
  const gp::FieldDescriptor* field = MapSettings::descriptor()->FindFieldByName(std::string(name));
  if (field == nullptr || field->is_repeated()) return nullptr;
  switch (field->cpp_type()) {
    case gp::FieldDescriptor::CPPTYPE_DOUBLE:
    case gp::FieldDescriptor::CPPTYPE_UINT32:
    case gp::FieldDescriptor::CPPTYPE_STRING:
    case gp::FieldDescriptor::CPPTYPE_ENUM:
      return field;
    default:
      return nullptr;
  }
}

std::string Unknown(std::string_view name) { return "unknown setting '" + std::string(name) + "'"; }

std::string FieldText(const MapSettings& settings, const gp::FieldDescriptor& field) {
  const gp::Reflection& reflection = *settings.GetReflection();
  switch (field.cpp_type()) {
    case gp::FieldDescriptor::CPPTYPE_DOUBLE: {
      char text[32];
      std::snprintf(text, sizeof(text), "%.17g", reflection.GetDouble(settings, &field));
      return text;
    }
    case gp::FieldDescriptor::CPPTYPE_UINT32:
      return std::to_string(reflection.GetUInt32(settings, &field));
    case gp::FieldDescriptor::CPPTYPE_STRING:
      return reflection.GetString(settings, &field);
    case gp::FieldDescriptor::CPPTYPE_ENUM: {
      // A number this build's enum does not name reads as the number (which nothing accepts).
      const int number = reflection.GetEnumValue(settings, &field);
      const gp::EnumValueDescriptor* value = field.enum_type()->FindValueByNumber(number);
      return value == nullptr ? std::to_string(number) : EnumText(*value);
    }
    default:  // Field() admits no other type
      return {};
  }
}

}  // namespace

std::string MapSettingsAsText(const MapSettings& settings, std::span<const std::string_view> names,
                              std::vector<std::pair<std::string, std::string>>* values) {
  values->clear();
  const gp::Reflection& reflection = *settings.GetReflection();
  for (const std::string_view name : names) {
    const gp::FieldDescriptor* field = Field(name);
    if (field == nullptr) {
      values->clear();
      return Unknown(name);
    }
    if (!reflection.HasField(settings, field)) continue;
    if (field->cpp_type() == gp::FieldDescriptor::CPPTYPE_ENUM &&
        reflection.GetEnumValue(settings, field) == 0) {
      continue;  // *_UNSPECIFIED: not given
    }
    values->emplace_back(std::string(name), FieldText(settings, *field));
  }
  return {};
}

std::string SetMapSettingFromText(MapSettings* settings, std::string_view name,
                                  std::string_view text) {
  const gp::FieldDescriptor* field = Field(name);
  if (field == nullptr) return Unknown(name);
  const std::string value(text);
  const std::string bad = std::string(name) + ": '" + value + "' is not ";
  const gp::Reflection& reflection = *settings->GetReflection();
  switch (field->cpp_type()) {
    case gp::FieldDescriptor::CPPTYPE_DOUBLE: {
      char* end = nullptr;
      const double number = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0') return bad + "a number";
      reflection.SetDouble(settings, field, number);
      return {};
    }
    case gp::FieldDescriptor::CPPTYPE_UINT32: {
      uint32_t number = 0;
      const auto [end, error] = std::from_chars(value.data(), value.data() + value.size(), number);
      if (value.empty() || error != std::errc() || end != value.data() + value.size()) {
        return bad + "a whole number from 0 to 4294967295";
      }
      reflection.SetUInt32(settings, field, number);
      return {};
    }
    case gp::FieldDescriptor::CPPTYPE_STRING:
      reflection.SetString(settings, field, value);
      return {};
    case gp::FieldDescriptor::CPPTYPE_ENUM: {
      const gp::EnumDescriptor& type = *field->enum_type();
      std::string names;
      for (int i = 1; i < type.value_count(); ++i) {  // 0 is *_UNSPECIFIED
        const std::string candidate = EnumText(*type.value(i));
        if (candidate == value) {
          reflection.SetEnum(settings, field, type.value(i));
          return {};
        }
        names += (names.empty() ? "" : ", ") + candidate;
      }
      return bad + "one of " + names;
    }
    default:  // Field() admits no other type
      return Unknown(name);
  }
}

}  // namespace recog

// Names of an enum's values, in one table per enum: the one place its strings are converted.
//
//   enum class Loss { kTrivial, kHuber };
//   inline constexpr EnumName<Loss> kLossNames[] = {{Loss::kTrivial, "trivial"},
//                                                  {Loss::kHuber, "huber"}};
//   NameOf(kLossNames, Loss::kHuber)              -> "huber"
//   ParseName(kLossNames, "huber", &loss)         -> true
//   YamlMap::GetEnum("type", kLossNames, &loss)   (util/yaml_reader.h)
// A value may have more than one name (an older spelling after the current one): NameOf gives
// the first, ParseName accepts each, and NamesOf lists each once.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace carmba {

template <typename E>
struct EnumName {
  E value;
  const char* name;
};

template <typename E, size_t N>
const char* NameOf(const EnumName<E> (&table)[N], E value) {
  for (const EnumName<E>& e : table) {
    if (e.value == value) return e.name;
  }
  return "?";
}

template <typename E, size_t N>
bool ParseName(const EnumName<E> (&table)[N], const std::string& name, E* out) {
  for (const EnumName<E>& e : table) {
    if (name == e.name) {
      *out = e.value;
      return true;
    }
  }
  return false;
}

// Every name, in the table's order.
template <typename E, size_t N>
std::vector<std::string> NamesOf(const EnumName<E> (&table)[N]) {
  std::vector<std::string> names;
  for (const EnumName<E>& e : table) names.emplace_back(e.name);
  return names;
}

// "a, b or c" (for messages).
template <typename E, size_t N>
std::string NameList(const EnumName<E> (&table)[N]) {
  std::string list;
  for (size_t i = 0; i < N; ++i) {
    list += (i == 0 ? "" : i + 1 == N ? " or " : ", ") + std::string(table[i].name);
  }
  return list;
}

}  // namespace carmba

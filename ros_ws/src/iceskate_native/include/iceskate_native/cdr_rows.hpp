// Messages in CDR written from the columns of a block of samples, one message per sample, by
// a program the caller computes from the message definitions (iceskate_sim.recording.cdr): a
// message is its skeleton (counts, strings, padding, numbers 0) with each number written at
// its offset, converted from the column's type to the field's.
#pragma once

#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

namespace iceskate_native
{

/// A column of a block of samples: `width` values per sample, row-major, of one type.
struct Column
{
  enum class Type : std::uint8_t { kFloat64, kInt64, kInt32, kUint64, kUint8 };

  const void * data = nullptr;
  Type type = Type::kFloat64;
  std::size_t width = 1;

  double real(std::size_t row, std::size_t element) const;
  std::int64_t integer(std::size_t row, std::size_t element) const;
};

/// The Column::Type of a column of T.
template <class T>
constexpr Column::Type column_type(const std::vector<T> &)
{
  if constexpr (std::is_same_v<T, double>) {
    return Column::Type::kFloat64;
  } else if constexpr (std::is_same_v<T, std::uint8_t>) {
    return Column::Type::kUint8;
  } else if constexpr (std::is_same_v<T, std::uint64_t>) {
    return Column::Type::kUint64;
  } else {
    static_assert(std::is_signed_v<T> && (sizeof(T) == 4 || sizeof(T) == 8));
    return sizeof(T) == 8 ? Column::Type::kInt64 : Column::Type::kInt32;
  }
}

/// How one number of a message is written: its type. kStamp writes builtin_interfaces/Time
/// from an integer column of nanoseconds >= 0: int32 sec, then uint32 nanosec.
enum class CdrWrite : std::uint8_t {
  kFloat64, kInt32, kUint32, kUint8, kStamp, kFloat32, kInt8, kInt16, kUint16, kInt64, kUint64
};

/// One number of a message: written at byte `offset` from element `element` of column
/// `column` of the sample.
struct CdrSlot
{
  std::uint32_t offset = 0;
  CdrWrite write = CdrWrite::kFloat64;
  std::uint32_t column = 0;
  std::uint32_t element = 0;
};

/// The messages of one layout: their skeleton and their numbers.
class CdrProgram
{
public:
  /// \throws std::invalid_argument for a slot that does not fit in the skeleton.
  CdrProgram(std::vector<std::uint8_t> skeleton, std::vector<CdrSlot> slots);

  std::size_t size() const noexcept { return skeleton_.size(); }
  const std::vector<CdrSlot> & slots() const noexcept { return slots_; }

  /// \throws std::invalid_argument for a slot whose column is not in `columns` or narrower
  /// than its element.
  void check(const std::vector<Column> & columns) const;

  /// Writes the message of sample `row` into `out` (size() bytes); `columns` checked.
  void write(const std::vector<Column> & columns, std::size_t row, std::uint8_t * out) const;

private:
  std::vector<std::uint8_t> skeleton_;
  std::vector<CdrSlot> slots_;
};

}  // namespace iceskate_native

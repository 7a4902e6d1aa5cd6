#include "iceskate_native/cdr_rows.hpp"

#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>

namespace iceskate_native
{

namespace
{

/// Bytes a slot writes.
std::size_t width_of(CdrWrite write)
{
  switch (write) {
    case CdrWrite::kFloat64:
    case CdrWrite::kStamp:
    case CdrWrite::kInt64:
    case CdrWrite::kUint64:
      return 8;
    case CdrWrite::kInt32:
    case CdrWrite::kUint32:
    case CdrWrite::kFloat32:
      return 4;
    case CdrWrite::kInt16:
    case CdrWrite::kUint16:
      return 2;
    case CdrWrite::kUint8:
    case CdrWrite::kInt8:
      return 1;
  }
  return 0;
}

/// `value` at `out` in the host's byte order (CDR little endian on the hosts we build for).
template <typename T>
void put(std::uint8_t * out, T value)
{
  std::memcpy(out, &value, sizeof(T));
}

/// Entry k of column data of type `type`, converted to T.
template <typename T>
T entry(const void * data, Column::Type type, std::size_t k)
{
  switch (type) {
    case Column::Type::kFloat64:
      return static_cast<T>(static_cast<const double *>(data)[k]);
    case Column::Type::kInt64:
      return static_cast<T>(static_cast<const std::int64_t *>(data)[k]);
    case Column::Type::kInt32:
      return static_cast<T>(static_cast<const std::int32_t *>(data)[k]);
    case Column::Type::kUint64:
      return static_cast<T>(static_cast<const std::uint64_t *>(data)[k]);
    case Column::Type::kUint8:
      return static_cast<T>(static_cast<const std::uint8_t *>(data)[k]);
  }
  return T{};
}

}  // namespace

double Column::real(std::size_t row, std::size_t element) const
{
  return entry<double>(data, type, row * width + element);
}

std::int64_t Column::integer(std::size_t row, std::size_t element) const
{
  return entry<std::int64_t>(data, type, row * width + element);
}

CdrProgram::CdrProgram(std::vector<std::uint8_t> skeleton, std::vector<CdrSlot> slots)
: skeleton_(std::move(skeleton)), slots_(std::move(slots))
{
  for (const CdrSlot & slot : slots_) {
    if (slot.offset + width_of(slot.write) > skeleton_.size()) {
      throw std::invalid_argument(
        "a number at byte " + std::to_string(slot.offset) + " does not fit in a message of "
        + std::to_string(skeleton_.size()) + " bytes");
    }
  }
}

void CdrProgram::check(const std::vector<Column> & columns) const
{
  for (const CdrSlot & slot : slots_) {
    if (slot.column >= columns.size() || slot.element >= columns[slot.column].width) {
      throw std::invalid_argument(
        "a number of the message reads element " + std::to_string(slot.element) + " of column "
        + std::to_string(slot.column) + ", which " + std::to_string(columns.size())
        + " columns do not hold");
    }
  }
}

void CdrProgram::write(
  const std::vector<Column> & columns, std::size_t row, std::uint8_t * out) const
{
  std::memcpy(out, skeleton_.data(), skeleton_.size());
  for (const CdrSlot & slot : slots_) {
    const Column & column = columns[slot.column];
    std::uint8_t * at = out + slot.offset;
    switch (slot.write) {
      case CdrWrite::kFloat64:
        put(at, column.real(row, slot.element));
        break;
      case CdrWrite::kInt32:
        put(at, static_cast<std::int32_t>(column.integer(row, slot.element)));
        break;
      case CdrWrite::kUint32:
        put(at, static_cast<std::uint32_t>(column.integer(row, slot.element)));
        break;
      case CdrWrite::kUint8:
        put(at, static_cast<std::uint8_t>(column.integer(row, slot.element)));
        break;
      case CdrWrite::kFloat32:
        put(at, static_cast<float>(column.real(row, slot.element)));
        break;
      case CdrWrite::kInt8:
        put(at, static_cast<std::int8_t>(column.integer(row, slot.element)));
        break;
      case CdrWrite::kInt16:
        put(at, static_cast<std::int16_t>(column.integer(row, slot.element)));
        break;
      case CdrWrite::kUint16:
        put(at, static_cast<std::uint16_t>(column.integer(row, slot.element)));
        break;
      case CdrWrite::kInt64:
        put(at, column.integer(row, slot.element));
        break;
      case CdrWrite::kUint64:
        put(at, static_cast<std::uint64_t>(column.integer(row, slot.element)));
        break;
      case CdrWrite::kStamp: {
        const std::int64_t ns = column.integer(row, slot.element);
        put(at, static_cast<std::int32_t>(ns / 1000000000));
        put(at + 4, static_cast<std::uint32_t>(ns % 1000000000));
        break;
      }
    }
  }
}

}  // namespace iceskate_native

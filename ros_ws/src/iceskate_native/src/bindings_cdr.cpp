// Bindings of the CDR message writer (cdr_rows.hpp), part of iceskate_native._kernel:
// CdrProgram from a skeleton and its slots, encode_rows over numpy columns.
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/vector.h>

#include "bindings.hpp"
#include "iceskate_native/cdr_rows.hpp"

namespace nb = nanobind;
using nb::literals::operator""_a;

namespace iceskate_native::bindings
{

namespace
{

using SlotArray = nb::ndarray<const std::uint32_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using AnyArray = nb::ndarray<nb::ro, nb::c_contig, nb::device::cpu>;

void construct_program(CdrProgram * self, const nb::bytes & skeleton, SlotArray slots)
{
  if (slots.shape(1) != 4) {
    throw std::invalid_argument("slots need 4 columns (offset, write, column, element)");
  }
  std::vector<CdrSlot> out(slots.shape(0));
  for (std::size_t k = 0; k < out.size(); ++k) {
    const std::uint32_t write = slots(k, 1);
    if (write > static_cast<std::uint32_t>(CdrWrite::kUint64)) {
      throw std::invalid_argument("unknown write code " + std::to_string(write));
    }
    out[k] = CdrSlot{slots(k, 0), static_cast<CdrWrite>(write), slots(k, 2), slots(k, 3)};
  }
  const auto * data = static_cast<const std::uint8_t *>(static_cast<const void *>(skeleton.c_str()));
  new (self) CdrProgram(std::vector<std::uint8_t>(data, data + skeleton.size()), std::move(out));
}

/// A numpy array of `rows` rows (1-D: one value per row; 2-D: its columns) as a Column.
Column column_of_array(const AnyArray & array, std::size_t rows, std::size_t index)
{
  const std::string which = "column " + std::to_string(index);
  if (array.ndim() < 1 || array.ndim() > 2 || array.shape(0) != rows) {
    throw std::invalid_argument(which + " does not have " + std::to_string(rows) + " rows");
  }
  Column column;
  column.data = array.data();
  column.width = array.ndim() == 2 ? array.shape(1) : 1;
  const nb::dlpack::dtype type = array.dtype();
  if (type == nb::dtype<double>()) {
    column.type = Column::Type::kFloat64;
  } else if (type == nb::dtype<std::int64_t>()) {
    column.type = Column::Type::kInt64;
  } else if (type == nb::dtype<std::int32_t>()) {
    column.type = Column::Type::kInt32;
  } else if (type == nb::dtype<std::uint64_t>()) {
    column.type = Column::Type::kUint64;
  } else if (type == nb::dtype<std::uint8_t>() || type == nb::dtype<bool>()) {
    column.type = Column::Type::kUint8;
  } else {
    throw std::invalid_argument(which + " is not float64, int64, int32, uint64, uint8 or bool");
  }
  return column;
}

nb::object encode_rows(const CdrProgram & program, const std::vector<AnyArray> & arrays,
                       std::size_t rows)
{
  std::vector<Column> columns;
  columns.reserve(arrays.size());
  for (std::size_t k = 0; k < arrays.size(); ++k) {
    columns.push_back(column_of_array(arrays[k], rows, k));
  }
  program.check(columns);
  auto * bytes = new std::vector<std::uint8_t>(rows * program.size());
  nb::capsule owner(bytes, [](void * p) noexcept {
    delete static_cast<std::vector<std::uint8_t> *>(p);
  });
  for (std::size_t row = 0; row < rows; ++row) {
    program.write(columns, row, bytes->data() + row * program.size());
  }
  return nb::cast(nb::ndarray<nb::numpy, std::uint8_t, nb::ndim<2>>(
    bytes->data(), {rows, program.size()}, owner));
}

}  // namespace

void bind_cdr(nb::module_ & m)
{
  nb::class_<CdrProgram>(
    m, "CdrProgram",
    "How the CDR messages of one layout are written from columns of samples: the skeleton "
    "(the message's bytes with its numbers 0) and one slot per number.")
    .def(
      "__init__", &construct_program, "skeleton"_a, "slots"_a,
      "slots: (n, 4) uint32: byte offset, write (0 float64, 1 int32, 2 uint32, 3 uint8, 4 "
      "builtin_interfaces/Time from nanoseconds, 5 float32, 6 int8, 7 int16, 8 uint16, 9 "
      "int64, 10 uint64), column, element. ValueError for a slot outside the skeleton.")
    .def_prop_ro("size", &CdrProgram::size, "Bytes of one message.");
  m.def(
    "encode_rows", &encode_rows, "program"_a, "columns"_a, "rows"_a,
    "(rows, size) uint8: the message of each of `rows` samples; columns: numpy arrays of "
    "`rows` rows (float64, int64, int32, uint64, uint8 or bool; 1-D or 2-D, C-contiguous) in "
    "the order the slots number them. ValueError for a column of another shape or type, or "
    "one a slot reads beyond.");
}

}  // namespace iceskate_native::bindings

#pragma once
/// \file
/// Shared pieces of the Python module `crumple._crumple`: NumPy views over library buffers and
/// the conversion of user arrays into positions and faces.

#include <crumple/core/types.hpp>
#include <crumple/core/vertex_view.hpp>
#include <crumple/detect/contact.hpp>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstddef>
#include <memory>
#include <vector>

namespace crumple::python {

namespace py = pybind11;

/// A read-only NumPy view of `shape`/`strides` (bytes) over `data`, keeping `owner` alive. No
/// copy: the array reads the library's storage for as long as it lives.
template <class T>
py::array readonly_view(const T* data, std::vector<py::ssize_t> shape,
                        std::vector<py::ssize_t> strides, py::handle owner) {
  py::array out(py::dtype::of<T>(), std::move(shape), std::move(strides), data, owner);
  py::detail::array_proxy(out.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return out;
}

/// Byte distance from `a` to `b` (fields of one record).
inline py::ssize_t gap(const void* a, const void* b) {
  return static_cast<const char*>(b) - static_cast<const char*>(a);
}

/// A column of records: `k` rows of `field`'s type at a stride of the record's size (a view
/// over the records, no copy). `inner` adds trailing dimensions (shape, byte strides).
template <class T, class Record>
py::array column(const std::vector<Record>& records, const T* field, std::vector<py::ssize_t> inner_shape,
                 std::vector<py::ssize_t> inner_strides, py::handle owner) {
  static const T kEmpty[4] = {};
  std::vector<py::ssize_t> shape{static_cast<py::ssize_t>(records.size())};
  std::vector<py::ssize_t> strides{static_cast<py::ssize_t>(sizeof(Record))};
  shape.insert(shape.end(), inner_shape.begin(), inner_shape.end());
  strides.insert(strides.end(), inner_strides.begin(), inner_strides.end());
  return readonly_view<T>(records.empty() ? kEmpty : field, std::move(shape), std::move(strides), owner);
}

/// Positions given from Python: a view over the caller's array when it is float64 or float32
/// with each row's x, y, z consecutive (C order, or rows of a wider or sliced buffer), otherwise
/// one copy made here (other dtypes, Fortran order, sequences). `Detector.update` passes `view`
/// on: the detector reads packed float64 in place and converts other views once itself.
struct PositionsArg {
  VertexView view;
  Positions storage;  // the binding's copy, when one was needed
  py::object keep;    // the array viewed, kept alive while `view` is used
  bool copied = false;  // `storage` made by the binding (or NumPy, from a sequence)
  /// The positions as doubles: the array in place when native, else converted into `storage`
  /// (once; `copied` becomes true).
  PositionsView doubles();
};
/// Throws ValueError unless `value` is a real (n, 3) array (`what` names the argument).
PositionsArg positions_arg(py::handle value, const char* what);

/// Faces from an (m, 3) integer array; ValueError on another shape, a non-integer dtype or an
/// id outside int32 (range and repeats are the library's checks, `TriMesh::create`).
std::vector<Face> faces_arg(py::handle value);

/// The contacts of one result (`crumple.Contacts`); every array made from it keeps `set` alive.
struct PyContacts {
  std::shared_ptr<const ContactSet> set;
};

void bind_errors(py::module_& m);
void bind_mesh(py::module_& m);
void bind_detect(py::module_& m);
void bind_ccd(py::module_& m);
void bind_sim(py::module_& m);

}  // namespace crumple::python

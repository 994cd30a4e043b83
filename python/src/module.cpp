/// The extension module `crumple._crumple`, re-exported by the package `crumple`.

#include "bindings.hpp"

#include <crumple/core/error.hpp>
#include <crumple/sim/simulation.hpp>

#include <cstdint>
#include <exception>
#include <limits>
#include <string>

namespace crumple::python {

namespace {

// Exception types, created once at import (module state lives as long as the interpreter).
PyObject* g_error = nullptr;
PyObject* g_parse_error = nullptr;
PyObject* g_input_error = nullptr;
PyObject* g_precondition_error = nullptr;
PyObject* g_divergence_error = nullptr;

py::object optional_int(const std::optional<std::int64_t>& v) {
  return v ? py::object(py::int_(*v)) : py::object(py::none());
}

/// Raises `type(what)` with attributes; never throws (it runs inside pybind11's translator).
void raise_with(PyObject* type, const char* what, const py::dict& attributes) {
  py::object instance = py::reinterpret_steal<py::object>(PyObject_CallFunction(type, "s", what));
  if (!instance) return;  // the call set its own Python error
  for (auto item : attributes) {
    PyObject_SetAttr(instance.ptr(), item.first.ptr(), item.second.ptr());
  }
  PyErr_SetObject(type, instance.ptr());
}

}  // namespace

void bind_errors(py::module_& m) {
  g_error = PyErr_NewExceptionWithDoc("crumple.Error",
                                      "Base of every error crumple raises (a ValueError).",
                                      PyExc_ValueError, nullptr);
  g_parse_error = PyErr_NewExceptionWithDoc(
      "crumple.ParseError",
      "A file that cannot be read or written or whose content is malformed. Attributes: file "
      "(str), line (int or None, 1-based, text formats), byte_offset (int or None, binary "
      "formats), message (str, without the location).",
      g_error, nullptr);
  g_input_error = PyErr_NewExceptionWithDoc(
      "crumple.InputError", "Invalid input that is not a file: a bad method spec, an invalid mesh.",
      g_error, nullptr);
  g_precondition_error = PyErr_NewExceptionWithDoc(
      "crumple.PreconditionError",
      "A violated API precondition of the library (a wrong positions count, a face id out of "
      "range in a writer); the message names the library's source file and line.",
      g_error, nullptr);
  g_divergence_error = PyErr_NewExceptionWithDoc(
      "crumple.DivergenceError",
      "A simulation step left non-finite or exploding positions; the simulation is back at the "
      "start of that frame. Attributes: frame (int, the frame being computed), step (int, "
      "1-based step of that frame), message (str).",
      g_error, nullptr);
  m.add_object("Error", py::handle(g_error));
  m.add_object("DivergenceError", py::handle(g_divergence_error));
  m.add_object("ParseError", py::handle(g_parse_error));
  m.add_object("InputError", py::handle(g_input_error));
  m.add_object("PreconditionError", py::handle(g_precondition_error));

  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const ParseError& e) {
      py::dict attributes;
      attributes["file"] = py::str(e.file());
      attributes["line"] = optional_int(e.line());
      attributes["byte_offset"] = optional_int(e.byte_offset());
      attributes["message"] = py::str(e.message());
      raise_with(g_parse_error, e.what(), attributes);
    } catch (const sim::DivergenceError& e) {
      py::dict attributes;
      attributes["frame"] = py::int_(e.frame());
      attributes["step"] = py::int_(e.step());
      attributes["message"] = py::str(e.what());
      raise_with(g_divergence_error, e.what(), attributes);
    } catch (const InputError& e) {
      PyErr_SetString(g_input_error, e.what());
    } catch (const PreconditionError& e) {
      PyErr_SetString(g_precondition_error, e.what());
    } catch (const Error& e) {
      PyErr_SetString(g_error, e.what());
    }
  });
}

PositionsArg positions_arg(py::handle value, const char* what) {
  PositionsArg out;
  const bool given_array = py::isinstance<py::array>(value);
  py::array array = py::array::ensure(value);
  if (!array) throw py::value_error(std::string(what) + ": expected an (n, 3) array");
  if (array.ndim() != 2 || array.shape(1) != 3) {
    throw py::value_error(std::string(what) + ": expected shape (n, 3), got " +
                          std::string(py::str(py::object(array.attr("shape")))));
  }
  const char kind = array.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u') {
    throw py::value_error(std::string(what) + ": expected a real dtype (float64, float32, ...), got " +
                          std::string(py::str(array.dtype())));
  }
  const auto n = static_cast<std::size_t>(array.shape(0));
  // float64 or float32 in native byte order, each row's x, y, z consecutive, rows at a positive
  // stride of at least a row: a view over the caller's memory (VertexView reads any address).
  const auto rows_of = [&](auto component) -> bool {
    using T = decltype(component);
    if (!py::array_t<T>::check_(array)) return false;
    const py::ssize_t row = array.strides(0), col = array.strides(1);
    if (n > 0 && (col != static_cast<py::ssize_t>(sizeof(T)) || row < static_cast<py::ssize_t>(3 * sizeof(T)))) {
      return false;
    }
    out.view = VertexView(static_cast<const T*>(array.data()), n, n > 0 ? static_cast<std::size_t>(row) : 0);
    return true;
  };
  if (rows_of(double{}) || rows_of(float{})) {
    out.keep = array;
    out.copied = !given_array;  // a list or other sequence was converted by NumPy
    return out;
  }
  using Dense = py::array_t<double, py::array::c_style | py::array::forcecast>;
  Dense dense = Dense::ensure(array);  // one converted copy (dtype and/or layout)
  if (!dense) throw py::error_already_set();
  out.storage.resize(n);
  const double* src = dense.data();
  for (std::size_t i = 0; i < n; ++i) out.storage[i] = Vec3(src[3 * i], src[3 * i + 1], src[3 * i + 2]);
  out.view = VertexView(PositionsView(out.storage));
  out.copied = true;
  return out;
}

PositionsView PositionsArg::doubles() {
  if (view.is_native()) return view.native();
  view.convert(storage);
  view = VertexView(PositionsView(storage));
  copied = true;
  return storage;
}

std::vector<Face> faces_arg(py::handle value) {
  py::array array = py::array::ensure(value);
  if (!array) throw py::value_error("faces: expected an (m, 3) integer array");
  if (array.ndim() != 2 || array.shape(1) != 3) {
    throw py::value_error("faces: expected shape (m, 3), got " +
                          std::string(py::str(py::object(array.attr("shape")))));
  }
  const char kind = array.dtype().kind();
  if (kind != 'i' && kind != 'u') {
    throw py::value_error("faces: expected an integer dtype, got " + std::string(py::str(array.dtype())));
  }
  auto wide = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(array);
  if (!wide) throw py::error_already_set();
  const auto m = static_cast<std::size_t>(wide.shape(0));
  std::vector<Face> faces(m);
  const std::int64_t* src = wide.data();
  for (std::size_t f = 0; f < m; ++f) {
    for (std::size_t k = 0; k < 3; ++k) {
      const std::int64_t id = src[3 * f + k];
      if (id < std::numeric_limits<Index>::min() || id > std::numeric_limits<Index>::max()) {
        throw py::value_error("faces: face " + std::to_string(f) + " has vertex id " +
                              std::to_string(id) + ", outside 32-bit range");
      }
      faces[f][k] = static_cast<Index>(id);
    }
  }
  return faces;
}

}  // namespace crumple::python

PYBIND11_MODULE(_crumple, m) {
  m.doc() =
      "crumple: self-collision detection on deformable triangle meshes (see the package "
      "docstring).";
  crumple::python::bind_errors(m);
  crumple::python::bind_mesh(m);
  crumple::python::bind_detect(m);
  crumple::python::bind_ccd(m);
  crumple::python::bind_sim(m);
}

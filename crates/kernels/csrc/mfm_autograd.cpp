// Bridge between libtorch's autograd and operations written in Rust.
//
// `mfm_custom_apply` runs a `torch::autograd::Function` whose forward and
// backward call back into Rust through function pointers, with an opaque
// per-call state owned by the autograd node (released through `drop`). Tensors
// cross the boundary as `at::Tensor*`, the representation tch uses for its
// `C_tensor` handles. Errors never unwind through Rust frames: Rust callbacks
// report failures through their return code and an error buffer, and C++
// exceptions are caught here and turned into an error string.
#include <ATen/ATen.h>
#include <ATen/Parallel.h>
#include <torch/csrc/autograd/custom_function.h>

#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

using torch::autograd::AutogradContext;
using torch::autograd::variable_list;

extern "C" {
// Computes outputs from inputs. `outputs` has room for `max_outputs` fresh
// tensors (ownership passes to C++); `*num_outputs` receives the count.
// Returns 0 on success, otherwise writes a NUL-terminated message to `err`.
typedef int32_t (*mfm_forward_fn)(void *state, at::Tensor *const *inputs,
                                  int64_t num_inputs, at::Tensor **outputs,
                                  int64_t max_outputs, int64_t *num_outputs,
                                  char *err, int64_t err_len);
// Computes one gradient per input from one gradient per output; a null
// entry in `grad_inputs` means "no gradient".
typedef int32_t (*mfm_backward_fn)(void *state, at::Tensor *const *grad_outputs,
                                   int64_t num_grad_outputs,
                                   at::Tensor **grad_inputs, int64_t num_inputs,
                                   char *err, int64_t err_len);
typedef void (*mfm_drop_fn)(void *state);
typedef void (*mfm_range_fn)(void *ctx, int64_t begin, int64_t end);
}

namespace {

constexpr int64_t kErrLen = 2048;
constexpr int64_t kMaxOutputs = 16;

// Owns the Rust state of one call; lives in the autograd node's saved data.
struct RustState : torch::CustomClassHolder {
  void *state;
  mfm_forward_fn forward;
  mfm_backward_fn backward;
  mfm_drop_fn drop;
  RustState(void *s, mfm_forward_fn f, mfm_backward_fn b, mfm_drop_fn d)
      : state(s), forward(f), backward(b), drop(d) {}
  ~RustState() override {
    if (state != nullptr) {
      drop(state);
    }
  }
  RustState(const RustState &) = delete;
  RustState &operator=(const RustState &) = delete;
};

at::Tensor take(at::Tensor *p) {
  if (p == nullptr) {
    return at::Tensor();
  }
  at::Tensor t = *p;
  delete p;
  return t;
}

struct RustFunction : public torch::autograd::Function<RustFunction> {
  // `inputs` must be a TensorList (not a std::vector) for autograd to
  // register its elements as the node's inputs.
  static variable_list forward(AutogradContext *ctx, at::TensorList inputs,
                               c10::intrusive_ptr<RustState> holder) {
    std::vector<at::Tensor *> in;
    in.reserve(inputs.size());
    for (const auto &t : inputs) {
      in.push_back(const_cast<at::Tensor *>(&t));
    }
    at::Tensor *out[kMaxOutputs] = {nullptr};
    int64_t n_out = 0;
    char err[kErrLen] = {0};
    int32_t rc = holder->forward(holder->state, in.data(),
                                 static_cast<int64_t>(in.size()), out,
                                 kMaxOutputs, &n_out, err, kErrLen);
    variable_list outputs;
    for (int64_t i = 0; i < n_out && i < kMaxOutputs; ++i) {
      outputs.push_back(take(out[i]));
    }
    if (rc != 0) {
      throw std::runtime_error(std::string(err));
    }
    for (auto &o : outputs) {
      if (!o.defined()) {
        throw std::runtime_error("mfm custom op: forward returned an undefined tensor");
      }
    }
    ctx->saved_data["rust"] = c10::IValue::make_capsule(holder);
    ctx->saved_data["n_in"] = static_cast<int64_t>(inputs.size());
    return outputs;
  }

  static variable_list backward(AutogradContext *ctx, variable_list grad_outputs) {
    auto capsule = ctx->saved_data["rust"].toCapsule();
    auto *holder = static_cast<RustState *>(capsule.get());
    int64_t n_in = ctx->saved_data["n_in"].toInt();
    std::vector<at::Tensor *> g;
    g.reserve(grad_outputs.size());
    for (auto &t : grad_outputs) {
      g.push_back(&t);
    }
    std::vector<at::Tensor *> grads(static_cast<size_t>(n_in), nullptr);
    char err[kErrLen] = {0};
    int32_t rc = holder->backward(holder->state, g.data(),
                                  static_cast<int64_t>(g.size()), grads.data(),
                                  n_in, err, kErrLen);
    variable_list result;
    result.reserve(static_cast<size_t>(n_in) + 1);
    for (auto *p : grads) {
      result.push_back(take(p));
    }
    if (rc != 0) {
      throw std::runtime_error(std::string(err));
    }
    // the holder argument of forward is not a tensor: no gradient
    result.emplace_back();
    return result;
  }
};

void write_error(const char *msg, char *err, int64_t err_len) {
  if (err == nullptr || err_len <= 0) {
    return;
  }
  std::strncpy(err, msg, static_cast<size_t>(err_len - 1));
  err[err_len - 1] = '\0';
}

}  // namespace

extern "C" {

// Applies a Rust-defined autograd function to `inputs`. On success the
// outputs are written to `outputs` (fresh tensors owned by the caller) and 0
// is returned. The state is released through `drop` when the autograd node
// dies (or right away when no graph is recorded or the call fails).
int32_t mfm_custom_apply(void *state, mfm_forward_fn forward,
                         mfm_backward_fn backward, mfm_drop_fn drop,
                         at::Tensor *const *inputs, int64_t num_inputs,
                         at::Tensor **outputs, int64_t max_outputs,
                         int64_t *num_outputs, char *err, int64_t err_len) {
  *num_outputs = 0;
  c10::intrusive_ptr<RustState> holder;
  try {
    holder = c10::make_intrusive<RustState>(state, forward, backward, drop);
  } catch (const std::exception &e) {
    drop(state);
    write_error(e.what(), err, err_len);
    return 1;
  }
  try {
    variable_list in;
    in.reserve(static_cast<size_t>(num_inputs));
    for (int64_t i = 0; i < num_inputs; ++i) {
      in.push_back(*inputs[i]);
    }
    at::TensorList list(in);
    variable_list out = RustFunction::apply(list, std::move(holder));
    if (static_cast<int64_t>(out.size()) > max_outputs) {
      write_error("mfm custom op: too many outputs", err, err_len);
      return 1;
    }
    for (size_t i = 0; i < out.size(); ++i) {
      outputs[i] = new at::Tensor(std::move(out[i]));
    }
    *num_outputs = static_cast<int64_t>(out.size());
    return 0;
  } catch (const std::exception &e) {
    write_error(e.what(), err, err_len);
    return 1;
  } catch (...) {
    write_error("mfm custom op: unknown C++ exception", err, err_len);
    return 1;
  }
}

// Runs `f(ctx, begin, end)` over chunks of [begin, end) on libtorch's
// intra-op thread pool (the threads that also run torch's own kernels).
void mfm_parallel_for(int64_t begin, int64_t end, int64_t grain, mfm_range_fn f,
                      void *ctx) {
  at::parallel_for(begin, end, grain,
                   [&](int64_t b, int64_t e) { f(ctx, b, e); });
}

// Whether the current thread runs inside an at::parallel_for region.
int32_t mfm_in_parallel_region() { return at::in_parallel_region() ? 1 : 0; }

}  // extern "C"

// Float32 tensors, the define-by-run autodiff graph, parameters and parameter groups.
//
// A Tensor is a cheap handle to a node of the current thread's Graph. Nodes and their buffers
// live in the graph's arena, which Graph::reset() rewinds after each step, so a steady-state
// training step does not call malloc per op. Parameters live outside the arena: they own their
// values and gradients, and their gradients accumulate across backward() calls until an
// optimiser (or zero_grad) clears them. See nn.h for a worked example.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <new>
#include <span>
#include <string>
#include <vector>

namespace indrive::nn {

inline constexpr int kMaxRank = 4;

// Shape of a row-major tensor with 0 (scalar) to 4 dimensions.
struct Shape {
  int rank = 0;
  std::array<std::int64_t, kMaxRank> dims{};

  Shape() = default;
  // Builds a shape from its dimensions, e.g. Shape{16, 64, 64, 3}; every dimension must be > 0.
  Shape(std::initializer_list<std::int64_t> d);
  // Dimension i; negative i counts from the end (-1 is the last dimension).
  std::int64_t operator[](int i) const;
  // Number of elements (1 for a scalar).
  std::int64_t numel() const;
  // Size of the last dimension (1 for a scalar); tensors are viewed as (rows, cols) matrices.
  std::int64_t cols() const { return rank == 0 ? 1 : dims[rank - 1]; }
  // Product of all dimensions but the last.
  std::int64_t rows() const { return numel() / cols(); }
  // Human-readable form such as "(16, 64, 3)", for error messages.
  std::string str() const;
  bool operator==(const Shape& other) const;
  bool operator!=(const Shape& other) const { return !(*this == other); }
};

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using MatrixMap = Eigen::Map<RowMatrix>;
using ConstMatrixMap = Eigen::Map<const RowMatrix>;

namespace detail {

// 64-byte aligned storage, so that parameter buffers have the same alignment in every run
// (Eigen's kernels peel loops by alignment, which changes the rounding of sums).
template <typename T>
struct AlignedAllocator {
  using value_type = T;
  AlignedAllocator() = default;
  template <typename U>
  AlignedAllocator(const AlignedAllocator<U>&) {}
  T* allocate(std::size_t n) {
    return static_cast<T*>(::operator new(n * sizeof(T), std::align_val_t(64)));
  }
  void deallocate(T* p, std::size_t) { ::operator delete(p, std::align_val_t(64)); }
  template <typename U>
  bool operator==(const AlignedAllocator<U>&) const {
    return true;
  }
};
using AlignedFloats = std::vector<float, AlignedAllocator<float>>;

struct Node;
// A value no parameter version has had in this process (versions are unique, so that a kept
// copy of a destroyed parameter never matches one made later at the same address).
std::uint64_t next_parameter_version();
// Reverse-mode rule of one op: reads node.grad and adds into the grads of node.in[...].
using BackwardFn = void (*)(Node& node);

// One value in the graph. Trivially destructible: nodes live in the arena and die on reset.
struct Node {
  Shape shape;
  float* value = nullptr;
  float* grad = nullptr;  // allocated (zeroed) when a gradient first flows into the node
  bool requires_grad = false;
  bool persistent = false;  // a parameter leaf: grad is owned by the Parameter
  BackwardFn backward = nullptr;
  Node* in[3] = {nullptr, nullptr, nullptr};
  float* saved = nullptr;  // op-specific buffer kept for backward (e.g. LayerNorm 1/std)
  // A view (reshape, contiguous slice) shares its source's gradient buffer at an offset, so
  // it needs no backward rule and no copy.
  Node* view_of = nullptr;
  std::int64_t view_offset = 0;
  float fparam[4] = {0, 0, 0, 0};
  std::int64_t iparam[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  // A parameter leaf's value version, bumped whenever its values are handed out for writing;
  // the kernel layer keeps a bf16 copy per version (kernels.h).
  std::uint64_t version = 0;
  // Graph::backward of several losses: one bit per loss whose gradient reaches this node
  // (cleared again before it returns).
  std::uint32_t reached_by = 0;
};

}  // namespace detail

// Handle to a tensor in a Graph (or to a Parameter's leaf). Copying copies the handle only.
class Tensor {
 public:
  Tensor() = default;
  explicit Tensor(detail::Node* node) : node_(node) {}

  // True when the handle refers to a tensor.
  bool defined() const { return node_ != nullptr; }
  // Shape of the tensor.
  const Shape& shape() const { return node_->shape; }
  // Number of elements.
  std::int64_t numel() const { return node_->shape.numel(); }
  // Rows of the (rows, cols) matrix view: product of all dimensions but the last.
  std::int64_t rows() const { return node_->shape.rows(); }
  // Size of the last dimension.
  std::int64_t cols() const { return node_->shape.cols(); }
  // Dimension i (negative counts from the end).
  std::int64_t dim(int i) const { return node_->shape[i]; }
  // Contiguous row-major values; writable so that inputs can be filled in place.
  float* data() const { return node_->value; }
  // Values as a span of numel() floats.
  std::span<float> values() const { return {node_->value, static_cast<size_t>(numel())}; }
  // Gradient after backward(), or nullptr when no gradient reached this tensor.
  const float* grad() const { return node_->grad; }
  // True when gradients flow to this tensor (it depends on a parameter or a grad leaf).
  bool requires_grad() const { return node_->requires_grad; }
  // The value of a one-element tensor.
  float item() const;
  // (rows, cols) row-major Eigen view of the values.
  MatrixMap matrix() const { return MatrixMap(node_->value, rows(), cols()); }
  // The underlying node (for op implementations).
  detail::Node* node() const { return node_; }

 private:
  detail::Node* node_ = nullptr;
};

// Records ops of one thread and owns the memory of their results. Not thread-safe: each
// thread uses its own graph (current_graph() is thread-local).
class Graph {
 public:
  Graph();
  ~Graph();
  Graph(const Graph&) = delete;
  Graph& operator=(const Graph&) = delete;

  // Runs reverse mode from a one-element loss: gradients accumulate into every tensor and
  // parameter the loss depends on. Call at most once per recorded graph.
  void backward(Tensor loss);
  // Reverse mode from several one-element losses, with the gradients of backward(l0 + l1 + ...).
  // Losses whose gradients meet in some tensor or parameter form one part; the parts' backward
  // passes run at once as tasks over the engine's threads (each part in the order one backward
  // would use, its ops single-threaded), so a parameter's gradient is the same for any thread
  // count. Gradient buffers live in this graph, as with one backward. At most 32 losses.
  // Returns the number of parts.
  //
  // `after`, when given, is called once for every loss i, as after(i), as soon as every
  // gradient of i's part is complete: on the thread that ran the part (under a NoGradGuard,
  // beside parts still running), for each of the part's losses in increasing order, and on the
  // calling thread for a loss that reaches no parameter. It may read and change what only its
  // part's losses reach (e.g. step the optimiser of those parameters), nothing else.
  int backward(std::span<const Tensor> losses, const std::function<void(int)>& after = nullptr);
  // Forgets every tensor of this step and rewinds the arena. Every block is kept (and so are its
  // already-touched pages), so a step that repeats the previous step's allocations gets the
  // same addresses and makes no system allocation and no page fault.
  void reset();
  // Returns all arena memory to the system (e.g. after a one-off large step); the next step
  // allocates afresh. Every tensor of the graph must be dead: it implies reset().
  void release_memory();
  // A position in the arena (see rewind()).
  struct Mark {
    std::size_t block = 0, used = 0, nodes = 0, tape = 0;
  };
  // The current position of the arena, to rewind to after a scratch computation.
  Mark mark() const;
  // Gives back everything allocated since `mark`, so that a long no-grad computation done in
  // chunks (e.g. scoring many imagined states) reuses one chunk's memory. Every tensor created
  // since `mark` must be dead, and no op may have been recorded since (checked).
  void rewind(const Mark& mark);
  // True unless a NoGradGuard is active: ops record backward rules only when enabled.
  bool grad_enabled() const { return grad_enabled_; }
  // Bytes currently handed out by the arena (values, gradients, nodes).
  std::size_t arena_used_bytes() const;
  // Bytes the arena holds from the system.
  std::size_t arena_capacity_bytes() const;
  // Largest arena_used_bytes() seen at a reset() since construction (or release_memory()).
  std::size_t arena_high_water_bytes() const { return high_water_; }
  // Number of system allocations the arena has made since construction (for allocation tests).
  std::size_t arena_system_allocations() const { return system_allocations_; }
  // Number of nodes recorded since the last reset.
  std::size_t num_nodes() const { return num_nodes_; }

  // Allocates n floats (64-byte aligned, uninitialised) that live until reset().
  float* alloc(std::int64_t n);
  // Allocates n zeroed floats that live until reset().
  float* alloc_zeroed(std::int64_t n);
  // Creates a node with an uninitialised value buffer of the given shape.
  detail::Node* new_node(const Shape& shape);
  // Creates a node whose value aliases `value` (views such as reshape and stop_gradient).
  detail::Node* new_view_node(const Shape& shape, float* value);
  // Makes `view` (from new_view_node) share the gradient of `source` at `offset` floats, when
  // grad mode is on and the source requires a gradient.
  void link_view(detail::Node* view, detail::Node* source, std::int64_t offset);
  // The gradient buffer of `node`, allocated zeroed on first use (views resolve to their
  // source's buffer); nullptr when the node takes no gradient.
  float* grad_buffer(detail::Node* node);
  // Like grad_buffer, but a buffer allocated by this call is left uninitialised and *fresh is
  // set: the caller must then write every element (saves zeroing large buffers).
  float* grad_buffer_for_write(detail::Node* node, bool* fresh);
  // Makes `node` the result of an op with inputs `in` and backward rule `fn`: it records the
  // node when grad mode is on and some input requires a gradient.
  void record(detail::Node* node, detail::BackwardFn fn, std::initializer_list<detail::Node*> in);

 private:
  friend class NoGradGuard;
  // One system allocation of the arena; blocks are only freed by release_memory() or the
  // destructor, never by reset(), so their pages stay mapped and touched between steps.
  struct Block {
    std::byte* memory = nullptr;
    std::size_t size = 0;
    std::size_t used = 0;
  };
  void* alloc_bytes(std::size_t bytes);
  void* alloc_bytes_unlocked(std::size_t bytes);
  void free_blocks();
  // Runs the recorded backward rules of `nodes` (reverse creation order) on the calling thread,
  // then after(i) for each loss i in the bit set `losses`.
  void run_backward_part(const std::vector<detail::Node*>& nodes, std::uint32_t losses,
                         const std::function<void(int)>& after);

  std::vector<Block> blocks_;
  std::size_t current_ = 0;  // index of the block that allocations are served from
  std::size_t high_water_ = 0;
  std::size_t system_allocations_ = 0;
  std::size_t num_nodes_ = 0;
  std::vector<detail::Node*> tape_;
  bool grad_enabled_ = true;
  // While backward parts run on several threads, allocations in this arena (gradient buffers
  // from every thread, scratch from the calling thread) take this lock.
  bool shared_ = false;
  std::mutex shared_mutex_;
};

// The graph that gradient buffers are allocated in: the current graph, except on a thread
// that runs a part of another graph's backward (Graph::backward of several losses).
Graph& gradient_graph();

// The calling thread's current graph; ops allocate their results here.
Graph& current_graph();

// Disables gradient recording on the current graph for its lifetime (inference in actors).
class NoGradGuard {
 public:
  NoGradGuard();
  ~NoGradGuard();
  NoGradGuard(const NoGradGuard&) = delete;
  NoGradGuard& operator=(const NoGradGuard&) = delete;

 private:
  bool previous_;
};

// A new tensor of the given shape with unspecified values, in the current graph.
Tensor empty(const Shape& shape);
// A new tensor filled with zeros.
Tensor zeros(const Shape& shape);
// A new tensor filled with `value`.
Tensor full(const Shape& shape, float value);
// A new tensor holding a copy of `values` (numel(shape) floats).
Tensor constant(const Shape& shape, std::span<const float> values);
// A new leaf that receives a gradient in backward() (inputs of gradient checks).
Tensor grad_leaf(const Shape& shape, std::span<const float> values);

// A trainable tensor with a name; owns its value and gradient. Not movable, because graph
// nodes point at it: create parameters through ParamGroup::add.
class Parameter {
 public:
  Parameter(std::string name, const Shape& shape);
  Parameter(const Parameter&) = delete;
  Parameter& operator=(const Parameter&) = delete;

  // Full name, unique within its group, e.g. "enc.conv0.w".
  const std::string& name() const { return name_; }
  // Shape of the parameter.
  const Shape& shape() const { return node_.shape; }
  // Number of elements.
  std::int64_t numel() const { return node_.shape.numel(); }
  // The values (numel() floats, row-major). The writable view counts as a write: it bumps the
  // version that the kernel layer's bf16 and blocked copies of the parameter are checked
  // against. Writes through a view taken earlier are seen by products from the next
  // Graph::reset() on (the copies also end with each graph).
  std::span<float> value() {
    node_.version = detail::next_parameter_version();
    return value_;
  }
  std::span<const float> value() const { return value_; }
  // The accumulated gradient (numel() floats).
  std::span<float> grad() { return grad_; }
  std::span<const float> grad() const { return grad_; }
  // Sets the gradient to zero.
  void zero_grad();
  // A handle to use the parameter in ops; gradients accumulate into grad().
  Tensor tensor() { return Tensor(&node_); }

 private:
  std::string name_;
  detail::AlignedFloats value_;
  detail::AlignedFloats grad_;
  detail::Node node_;
};

// A named, ordered set of parameters (e.g. "world_model", "actor", "critic"). Optimisers,
// EMA copies and serialization work on groups.
class ParamGroup {
 public:
  explicit ParamGroup(std::string name);
  ParamGroup(const ParamGroup&) = delete;
  ParamGroup& operator=(const ParamGroup&) = delete;

  // Name of the group.
  const std::string& name() const { return name_; }
  // Creates a zero-initialised parameter; a duplicate name is a bug (checked).
  Parameter& add(const std::string& name, const Shape& shape);
  // The parameters in creation order.
  const std::vector<std::unique_ptr<Parameter>>& params() const { return params_; }
  // The parameter with this name, or nullptr.
  Parameter* find(const std::string& name) const;
  // Total number of scalars over all parameters.
  std::int64_t numel() const;
  // Zeroes every gradient of the group.
  void zero_grad();

 private:
  std::string name_;
  std::vector<std::unique_ptr<Parameter>> params_;
};

// Small, fast, platform-independent random generator (xoshiro256**), so runs with a fixed
// seed give identical numbers everywhere.
class Rng {
 public:
  // Seeds the four state words from `seed` with splitmix64.
  explicit Rng(std::uint64_t seed = 0);
  // Next 64 random bits.
  std::uint64_t next_u64();
  // Uniform in [0, 1).
  float uniform();
  // Standard normal (Box-Muller).
  float normal();
  // Uniform integer in [0, n).
  std::int64_t below(std::int64_t n);

 private:
  std::uint64_t s_[4];
};

// Sets the number of threads used by the engine (OpenMP loops; large GEMMs are split over
// them, small ops stay on the calling thread). With one thread and a fixed seed, results are
// bitwise reproducible. Its threads then flush denormals (flush_denormals()).
void set_threads(int threads);
// Makes the calling thread and the engine's OpenMP threads treat denormal floats (magnitudes
// below 1.2e-38) as zero, in inputs and results (x86 FTZ and DAZ; elsewhere nothing): ops
// whose results underflow ran 1.3-1.4x (vector code) and 4.4x (scalar) slower without it on the
// development machine, and small probabilities, gradients and Adam moments can underflow.
// Called by set_threads and by every agent and policy on its thread. Returns whether it is done.
bool flush_denormals();
// The number of threads set by set_threads (default: OpenMP's default).
int threads();

// Runs task(i) for every i in [0, n), spread over the engine's threads one task at a time, for
// independent pieces of work that are each too small to split well op by op (scoring imagined
// states in chunks). A task runs on one thread, on that thread's own graph
// (current_graph() is thread-local), so its ops run single-threaded: results do not depend on
// the thread count. A task records nothing for backward (it runs under a NoGradGuard), and what
// it allocates in its graph is given back when it returns (a rewind), so it copies its results
// out, e.g. into rows of a tensor of the caller. Tasks may read tensors of the calling thread's
// graph. The first exception a task throws is rethrown once all have run.
void parallel_tasks(std::int64_t n, const std::function<void(std::int64_t)>& task);

}  // namespace indrive::nn

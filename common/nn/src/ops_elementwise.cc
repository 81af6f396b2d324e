// Elementwise ops: broadcasting binary ops, scalar ops and unary functions with their
// derivatives. Forward passes use Eigen's vectorised array functions.
#include <cmath>

#include "indrive/nn/ops.h"
#include "ops_internal.h"

namespace indrive::nn {

using detail::Array;
using detail::ConstArray;
using detail::grad_of;
using detail::Node;
using detail::parallel_for;

// ---- Broadcasting binary ops ----

namespace {

// gx = e when the gradient buffer is fresh (uninitialised), gx += e otherwise.
template <typename E>
void Put(Array& gx, const E& e, bool assign) {
  if (assign)
    gx = e;
  else
    gx += e;
}

enum BinaryKind : std::int64_t { kAdd, kSub, kMul, kDiv };

// (rows, cols) view of an operand and whether each axis is broadcast (size 1 against > 1).
struct Operand {
  const float* p;
  std::int64_t rstride;  // 0 when broadcast over rows, else cols of the operand
  std::int64_t cstride;  // 0 when broadcast over cols, else 1
};

// Output (rows, cols) of broadcasting a and b.
void broadcast_dims(const Shape& a, const Shape& b, std::int64_t& rows, std::int64_t& cols) {
  const std::int64_t ra = a.rows(), ca = a.cols(), rb = b.rows(), cb = b.cols();
  INDRIVE_CHECK((ra == rb || ra == 1 || rb == 1) && (ca == cb || ca == 1 || cb == 1))
      << "cannot broadcast " << a.str() << " with " << b.str();
  rows = std::max(ra, rb);
  cols = std::max(ca, cb);
}

template <int SA, int SB>
void binary_row(BinaryKind k, const float* a, const float* b, float* out, std::int64_t n) {
  switch (k) {
    case kAdd:
      for (std::int64_t c = 0; c < n; ++c) out[c] = a[c * SA] + b[c * SB];
      break;
    case kSub:
      for (std::int64_t c = 0; c < n; ++c) out[c] = a[c * SA] - b[c * SB];
      break;
    case kMul:
      for (std::int64_t c = 0; c < n; ++c) out[c] = a[c * SA] * b[c * SB];
      break;
    default:
      for (std::int64_t c = 0; c < n; ++c) out[c] = a[c * SA] / b[c * SB];
      break;
  }
}

void binary_forward(BinaryKind k, Operand a, Operand b, float* out, std::int64_t rows,
                    std::int64_t cols) {
  if (a.rstride == cols && b.rstride == cols && a.cstride == 1 && b.cstride == 1) {
    // Same shape: one flat vectorised loop.
    parallel_for(rows * cols, [&](std::int64_t s, std::int64_t e) {
      binary_row<1, 1>(k, a.p + s, b.p + s, out + s, e - s);
    });
    return;
  }
  for (std::int64_t r = 0; r < rows; ++r) {
    const float* ap = a.p + r * a.rstride;
    const float* bp = b.p + r * b.rstride;
    float* op = out + r * cols;
    if (a.cstride && b.cstride)
      binary_row<1, 1>(k, ap, bp, op, cols);
    else if (a.cstride)
      binary_row<1, 0>(k, ap, bp, op, cols);
    else if (b.cstride)
      binary_row<0, 1>(k, ap, bp, op, cols);
    else
      binary_row<0, 0>(k, ap, bp, op, cols);
  }
}

Operand operand(const Node* n, std::int64_t rows, std::int64_t cols) {
  const std::int64_t r = n->shape.rows(), c = n->shape.cols();
  return {n->value, (r == 1 && rows > 1) ? 0 : c, (c == 1 && cols > 1) ? 0 : 1};
}

void binary_backward(Node& n) {
  const auto kind = static_cast<BinaryKind>(n.iparam[0]);
  const std::int64_t rows = n.iparam[1], cols = n.iparam[2];
  Node* na = n.in[0];
  Node* nb = n.in[1];
  const Operand a = operand(na, rows, cols);
  const Operand b = operand(nb, rows, cols);
  const float* gy = n.grad;
  const float* y = n.value;
  const bool same = a.rstride == cols && b.rstride == cols && a.cstride == 1 && b.cstride == 1;
  if (same) {
    // One pass per input, each assigning into a gradient buffer that nothing has written yet
    // (saves zeroing it) or accumulating. When both inputs are the same node, the second pass
    // finds the buffer written by the first and accumulates.
    const std::int64_t total = rows * cols;
    bool fresh_a = false;
    float* ga = detail::grad_for_write(na, &fresh_a);
    if (ga != nullptr) {
      parallel_for(total, [&](std::int64_t s, std::int64_t e) {
        const std::int64_t len = e - s;
        Array g(ga + s, len);
        const ConstArray up(gy + s, len);
        switch (kind) {
          case kAdd:
          case kSub:
            Put(g, up, fresh_a);
            break;
          case kMul:
            Put(g, up * ConstArray(b.p + s, len), fresh_a);
            break;
          default:
            Put(g, up / ConstArray(b.p + s, len), fresh_a);
            break;
        }
      });
    }
    bool fresh_b = false;
    float* gb = detail::grad_for_write(nb, &fresh_b);
    if (gb != nullptr) {
      parallel_for(total, [&](std::int64_t s, std::int64_t e) {
        const std::int64_t len = e - s;
        Array g(gb + s, len);
        const ConstArray up(gy + s, len);
        switch (kind) {
          case kAdd:
            Put(g, up, fresh_b);
            break;
          case kSub:
            Put(g, -up, fresh_b);
            break;
          case kMul:
            Put(g, up * ConstArray(a.p + s, len), fresh_b);
            break;
          default:
            Put(g, -(up * ConstArray(y + s, len) / ConstArray(b.p + s, len)), fresh_b);
            break;
        }
      });
    }
    return;
  }
  float* ga = grad_of(na);
  float* gb = grad_of(nb);
  // Broadcast case: accumulate with strides; broadcast axes sum up (serial, deterministic).
  for (std::int64_t r = 0; r < rows; ++r) {
    for (std::int64_t c = 0; c < cols; ++c) {
      const std::int64_t i = r * cols + c;
      const std::int64_t ia = r * a.rstride + c * a.cstride;
      const std::int64_t ib = r * b.rstride + c * b.cstride;
      const float g = gy[i];
      switch (kind) {
        case kAdd:
          if (ga) ga[ia] += g;
          if (gb) gb[ib] += g;
          break;
        case kSub:
          if (ga) ga[ia] += g;
          if (gb) gb[ib] -= g;
          break;
        case kMul:
          if (ga) ga[ia] += g * b.p[ib];
          if (gb) gb[ib] += g * a.p[ia];
          break;
        default:
          if (ga) ga[ia] += g / b.p[ib];
          if (gb) gb[ib] -= g * y[i] / b.p[ib];
          break;
      }
    }
  }
}

Tensor binary(BinaryKind kind, Tensor a, Tensor b) {
  INDRIVE_CHECK(a.defined() && b.defined()) << "binary op on an undefined tensor";
  std::int64_t rows = 0, cols = 0;
  broadcast_dims(a.shape(), b.shape(), rows, cols);
  Shape out_shape;
  if (a.rows() == rows && a.cols() == cols)
    out_shape = a.shape();
  else if (b.rows() == rows && b.cols() == cols)
    out_shape = b.shape();
  else
    out_shape = Shape{rows, cols};
  Graph& g = current_graph();
  Node* n = g.new_node(out_shape);
  binary_forward(kind, operand(a.node(), rows, cols), operand(b.node(), rows, cols), n->value, rows,
                 cols);
  n->iparam[0] = kind;
  n->iparam[1] = rows;
  n->iparam[2] = cols;
  g.record(n, binary_backward, {a.node(), b.node()});
  return Tensor(n);
}

}  // namespace

Tensor add(Tensor a, Tensor b) { return binary(kAdd, a, b); }
Tensor sub(Tensor a, Tensor b) { return binary(kSub, a, b); }
Tensor mul(Tensor a, Tensor b) { return binary(kMul, a, b); }
Tensor div(Tensor a, Tensor b) { return binary(kDiv, a, b); }

// ---- Unary ops ----
//
// Each op is a struct with Forward(x, y, p) and Backward(x, y, gy, gx, p, assign) over array
// maps; Backward accumulates into gx, or assigns when gx is a fresh buffer. p points at the node's
// float parameters.

namespace {

struct ScaleOp {
  static void Forward(ConstArray x, Array y, const float* p) { y = x * p[0]; }
  static void Backward(ConstArray, ConstArray, ConstArray gy, Array gx, const float* p,
                       bool assign) {
    Put(gx, gy * p[0], assign);
  }
};
struct AddScalarOp {
  static void Forward(ConstArray x, Array y, const float* p) { y = x + p[0]; }
  static void Backward(ConstArray, ConstArray, ConstArray gy, Array gx, const float*, bool assign) {
    Put(gx, gy, assign);
  }
};
struct RsubScalarOp {
  static void Forward(ConstArray x, Array y, const float* p) { y = p[0] - x; }
  static void Backward(ConstArray, ConstArray, ConstArray gy, Array gx, const float*, bool assign) {
    Put(gx, -gy, assign);
  }
};
struct SigmoidOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x.logistic(); }
  static void Backward(ConstArray, ConstArray y, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, gy * y * (1.0f - y), assign);
  }
};
struct SiluOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x * x.logistic(); }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float*,
                       bool assign) {
    // d/dx x s(x) = s(x) (1 + x (1 - s(x))).
    Put(gx, gy * (x.logistic() * (1.0f + x * (1.0f - x.logistic()))), assign);
  }
};
struct EluOp {
  static void Forward(ConstArray x, Array y, const float*) {
    y = (x > 0.0f).select(x, x.exp() - 1.0f);
  }
  static void Backward(ConstArray x, ConstArray y, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, (x > 0.0f).select(gy, gy * (y + 1.0f)), assign);
  }
};
struct ReluOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x.max(0.0f); }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, (x > 0.0f).select(gy, 0.0f), assign);
  }
};
struct TanhOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x.tanh(); }
  static void Backward(ConstArray, ConstArray y, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, gy * (1.0f - y.square()), assign);
  }
};
struct ExpOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x.exp(); }
  static void Backward(ConstArray, ConstArray y, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, gy * y, assign);
  }
};
struct LogOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x.log(); }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, gy / x, assign);
  }
};
struct SquareOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x.square(); }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, 2.0f * gy * x, assign);
  }
};
struct SqrtOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x.sqrt(); }
  static void Backward(ConstArray, ConstArray y, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, 0.5f * gy / y, assign);
  }
};
struct SoftplusOp {
  static void Forward(ConstArray x, Array y, const float*) {
    y = x.max(0.0f) + (-x.abs()).exp().log1p();
  }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, gy * x.logistic(), assign);
  }
};
struct SymlogOp {
  static void Forward(ConstArray x, Array y, const float*) { y = x.sign() * x.abs().log1p(); }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, gy / (1.0f + x.abs()), assign);
  }
};
struct SymexpOp {
  static void Forward(ConstArray x, Array y, const float*) {
    y = x.sign() * (x.abs().exp() - 1.0f);
  }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float*,
                       bool assign) {
    Put(gx, gy * x.abs().exp(), assign);
  }
};
struct ClampOp {
  static void Forward(ConstArray x, Array y, const float* p) { y = x.max(p[0]).min(p[1]); }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float* p,
                       bool assign) {
    Put(gx, (x >= p[0] && x <= p[1]).select(gy, 0.0f), assign);
  }
};
struct MaximumOp {
  static void Forward(ConstArray x, Array y, const float* p) { y = x.max(p[0]); }
  static void Backward(ConstArray x, ConstArray, ConstArray gy, Array gx, const float* p,
                       bool assign) {
    Put(gx, (x >= p[0]).select(gy, 0.0f), assign);
  }
};

template <typename Op>
void unary_backward(Node& n) {
  bool fresh = false;
  float* gx = detail::grad_for_write(n.in[0], &fresh);
  if (gx == nullptr) return;
  const float* x = n.in[0]->value;
  const float* y = n.value;
  const float* gy = n.grad;
  const float* p = n.fparam;
  parallel_for(n.shape.numel(), [&](std::int64_t s, std::int64_t e) {
    const std::int64_t len = e - s;
    Op::Backward(ConstArray(x + s, len), ConstArray(y + s, len), ConstArray(gy + s, len),
                 Array(gx + s, len), p, fresh);
  });
}

template <typename Op>
Tensor unary(Tensor x, float p0 = 0.0f, float p1 = 0.0f) {
  INDRIVE_CHECK(x.defined()) << "unary op on an undefined tensor";
  Graph& g = current_graph();
  Node* n = g.new_node(x.shape());
  n->fparam[0] = p0;
  n->fparam[1] = p1;
  const float* xv = x.data();
  float* y = n->value;
  parallel_for(x.numel(), [&](std::int64_t s, std::int64_t e) {
    Op::Forward(ConstArray(xv + s, e - s), Array(y + s, e - s), n->fparam);
  });
  g.record(n, unary_backward<Op>, {x.node()});
  return Tensor(n);
}

}  // namespace

Tensor scale(Tensor x, float s) { return unary<ScaleOp>(x, s); }
Tensor add_scalar(Tensor x, float c) { return unary<AddScalarOp>(x, c); }
Tensor rsub_scalar(float c, Tensor x) { return unary<RsubScalarOp>(x, c); }
Tensor silu(Tensor x) { return unary<SiluOp>(x); }
Tensor elu(Tensor x) { return unary<EluOp>(x); }
Tensor relu(Tensor x) { return unary<ReluOp>(x); }
Tensor sigmoid(Tensor x) { return unary<SigmoidOp>(x); }
Tensor tanh(Tensor x) { return unary<TanhOp>(x); }
Tensor exp(Tensor x) { return unary<ExpOp>(x); }
Tensor log(Tensor x) { return unary<LogOp>(x); }
Tensor square(Tensor x) { return unary<SquareOp>(x); }
Tensor sqrt(Tensor x) { return unary<SqrtOp>(x); }
Tensor softplus(Tensor x) { return unary<SoftplusOp>(x); }
Tensor symlog(Tensor x) { return unary<SymlogOp>(x); }
Tensor symexp(Tensor x) { return unary<SymexpOp>(x); }
Tensor clamp(Tensor x, float lo, float hi) {
  INDRIVE_CHECK_LE(lo, hi) << "clamp bounds";
  return unary<ClampOp>(x, lo, hi);
}
Tensor maximum(Tensor x, float c) { return unary<MaximumOp>(x, c); }

}  // namespace indrive::nn

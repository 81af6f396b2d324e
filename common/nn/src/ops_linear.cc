// Matrix product and the fused linear layer (x * w + b) on the kernel layer's products.
#include "indrive/nn/ops.h"
#include "ops_internal.h"

namespace indrive::nn {

using detail::cmat;
using detail::grad_of;
using detail::held;
using detail::mat;
using detail::Node;
using detail::operand;

namespace {

// Inputs: x (M, K), w (K, N), optional bias (N). Output y (M, N).
void linear_backward(Node& n) {
  Node* x = n.in[0];
  Node* w = n.in[1];
  Node* b = n.in[2];
  const std::int64_t m = n.iparam[0], k = n.iparam[1], cols = n.iparam[2];
  // n.grad is final here, so its bf16 copy (where products run in bf16) serves both products.
  const auto gy = detail::final_grad(detail::operand(cmat(n.grad, m, cols)));
  bool fresh = false;
  if (float* gx = detail::grad_for_write(x, &fresh))
    detail::gemm(mat(gx, m, k), gy, held(operand(cmat(w->value, k, cols).transpose()), w), !fresh);
  if (float* gw = grad_of(w))
    detail::gemm(mat(gw, k, cols), held(operand(cmat(x->value, m, k).transpose()), x), gy, true);
  if (float* gb = grad_of(b)) mat(gb, 1, cols) += cmat(n.grad, m, cols).colwise().sum();
}

Tensor linear_impl(Tensor x, Tensor w, Tensor bias) {
  INDRIVE_CHECK(x.defined() && w.defined()) << "matmul of an undefined tensor";
  INDRIVE_CHECK_EQ(w.shape().rank, 2) << "weight must be 2-D, got " << w.shape().str();
  const std::int64_t k = w.dim(0), cols = w.dim(1);
  INDRIVE_CHECK_EQ(x.cols(), k) << "matmul " << x.shape().str() << " x " << w.shape().str();
  const std::int64_t m = x.rows();
  Graph& g = current_graph();
  Node* n = g.new_node(detail::with_last(x.shape(), cols));
  auto y = mat(n->value, m, cols);
  detail::gemm(y, held(operand(cmat(x.data(), m, k)), x.node()),
               held(operand(cmat(w.data(), k, cols)), w.node()), false);
  if (bias.defined()) {
    INDRIVE_CHECK_EQ(bias.numel(), cols) << "bias of shape " << bias.shape().str();
    y.rowwise() += cmat(bias.data(), 1, cols).row(0);
  }
  n->iparam[0] = m;
  n->iparam[1] = k;
  n->iparam[2] = cols;
  g.record(n, linear_backward, {x.node(), w.node(), bias.defined() ? bias.node() : nullptr});
  return Tensor(n);
}

}  // namespace

Tensor matmul(Tensor a, Tensor b) { return linear_impl(a, b, Tensor()); }
Tensor linear(Tensor x, Tensor w, Tensor bias) { return linear_impl(x, w, bias); }

}  // namespace indrive::nn

// The neural-network engine: float32 tensors on Eigen, define-by-run reverse-mode autodiff,
// DreamerV3's ops and layers, Adam, EMA and parameter serialization.
//
// Worked example: one training step of a small MLP regressor.
//
//   using namespace indrive::nn;
//   Rng rng(7);
//   ParamGroup model("model");
//   Mlp net(model, "net", /*in=*/3, {.units = 64, .layers = 2, .out = 1}, rng);
//   Adam adam(model, {.lr = 1e-3f});
//   for (int step = 0; step < 1000; ++step) {
//     Graph& graph = current_graph();
//     graph.reset();                                   // rewind the arena, keep its memory
//     Tensor x = constant({32, 3}, batch_inputs);      // (32, 3)
//     Tensor y = constant({32, 1}, batch_targets);     // (32, 1)
//     Tensor loss = mse(net(x), y);                    // scalar
//     graph.backward(loss);                            // grads accumulate into model's params
//     adam.step();                                     // clip, update, zero the grads
//   }
//
// Several models trained in one step, whose losses share no parameter (a world model and an
// actor-critic on stop-gradient features): graph.backward(std::vector<Tensor>{wm_loss, ac_loss})
// gives the gradients of their sum and runs the independent parts side by side on the engine's
// threads (tensor.h).
//
// Inference without a tape (actors): wrap the forward pass in a NoGradGuard and call
// current_graph().reset() once per step. Tensors die at reset(); copy out what must survive.
// Parameters are saved and restored with save_params / load_params (serialize.h).
#pragma once

#include "indrive/nn/layers.h"
#include "indrive/nn/ops.h"
#include "indrive/nn/optim.h"
#include "indrive/nn/serialize.h"
#include "indrive/nn/tensor.h"

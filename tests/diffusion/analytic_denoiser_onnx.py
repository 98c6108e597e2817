#!/usr/bin/env python3
"""Writes the analytic Gaussian denoiser (services/generation/diffusion/analytic_denoiser.h) as an
ONNX model, for onnx_denoiser_test: with the condition latent c as the data mean and s^2 the data
variance,
    eps = sqrt(1 - a) (x - sqrt(a) c) / (a (s^2 - 1) + 1),
a graph of element-wise ops OpenCV 4.6's ONNX importer runs. Needs Debian's python3-onnx (it is
run with /usr/bin/python3). Variants for the failure tests: "nan" (sqrt of a negative number) and
"short" (a mean over the latent: one value instead of C*H*W).

Usage: analytic_denoiser_onnx.py OUT.onnx C H W VARIANCE [plain|nan|short]
"""
import sys

import onnx
from onnx import TensorProto, helper


def main():
    out, c, h, w, variance = sys.argv[1], *map(int, sys.argv[2:5]), float(sys.argv[5])
    variant = sys.argv[6] if len(sys.argv) > 6 else "plain"
    shape = [1, c, h, w]
    inputs = [helper.make_tensor_value_info(n, TensorProto.FLOAT, shape)
              for n in ("x", "alpha_bar", "cond")]
    consts = [helper.make_tensor("one", TensorProto.FLOAT, [1], [1.0]),
              helper.make_tensor("var_minus_one", TensorProto.FLOAT, [1], [variance - 1.0])]
    nodes = [
        helper.make_node("Sqrt", ["alpha_bar"], ["sqrt_a"]),
        helper.make_node("Mul", ["sqrt_a", "cond"], ["mean_t"]),
        helper.make_node("Sub", ["x", "mean_t"], ["centred"]),
        helper.make_node("Sub", ["one", "alpha_bar"], ["one_minus_a"]),
        helper.make_node("Sqrt", ["one_minus_a"], ["sqrt_one_minus_a"]),
        helper.make_node("Mul", ["sqrt_one_minus_a", "centred"], ["numerator"]),
        helper.make_node("Mul", ["alpha_bar", "var_minus_one"], ["scaled"]),
        helper.make_node("Add", ["scaled", "one"], ["denominator"]),
    ]
    final = "eps"
    if variant == "nan":
        nodes.append(helper.make_node("Sub", ["alpha_bar", "one"], ["negative"]))
        nodes.append(helper.make_node("Sqrt", ["negative"], ["not_a_number"]))
        nodes.append(helper.make_node("Add", ["numerator", "not_a_number"], ["poisoned"]))
        nodes.append(helper.make_node("Div", ["poisoned", "denominator"], [final]))
        out_shape = shape
    elif variant == "short":
        nodes.append(helper.make_node("Div", ["numerator", "denominator"], ["full"]))
        nodes.append(helper.make_node("ReduceMean", ["full"], [final], axes=[1, 2, 3],
                                      keepdims=1))
        out_shape = [1, 1, 1, 1]
    else:
        nodes.append(helper.make_node("Div", ["numerator", "denominator"], [final]))
        out_shape = shape
    outputs = [helper.make_tensor_value_info(final, TensorProto.FLOAT, out_shape)]
    graph = helper.make_graph(nodes, "analytic_gaussian_denoiser", inputs, outputs, consts)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, out)


if __name__ == "__main__":
    main()

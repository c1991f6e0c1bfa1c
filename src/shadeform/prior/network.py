"""The shape prior's network: a small U-Net, its training in JAX, its export to ONNX.

Photo and mask in, normals and their uncertainty out, at :data:`SIZE` x :data:`SIZE` pixels (the
object framed by :func:`shadeform.prior.frame`). The architecture is written twice on purpose:
once in JAX (:func:`apply`, what trains) and once as an ONNX graph (:func:`to_onnx`, what ships
and runs on the CPU through onnxruntime); ``tests/test_prior.py`` holds the two equal on random
weights.

Layout. Inputs ``(N, 2, S, S)``: the photo scaled by its 99.9th percentile inside the mask and
zeroed outside it, and the mask. Each level of the encoder is two 3x3 convolutions with ReLU, then
a 2x2 average pool; the decoder doubles the size (nearest neighbour), concatenates the encoder's
features of that size and applies two 3x3 convolutions. Output ``(N, 4, S, S)``: an unnormalised
normal (3) and ``log s``, the log of the expected angular error's scale (radians) used as the
certainty: the training loss is the Laplace negative log-likelihood ``e / s + log s`` of the
chord ``e = |n - n_true|``, so ``s`` learns how far off the normal is likely to be.

This module needs the training extra (``pip install 'shadeform[train]'``: JAX, optax, onnx) except
for the names the package's inference uses, which need none of them.

References
----------
.. [1] O. Ronneberger, P. Fischer and T. Brox, "U-Net: convolutional networks for biomedical
   image segmentation", MICCAI 2015.
.. [2] A. Kendall and Y. Gal, "What uncertainties do we need in Bayesian deep learning for
   computer vision?", NeurIPS 2017 (the learned aleatoric scale).
"""

from __future__ import annotations

import numpy as np

#: Side (pixels) of the square the network sees; the object is framed into it.
SIZE = 128
#: Channels of each encoder level; the last is the bottleneck (at SIZE / 16).
WIDTHS = (16, 32, 64, 128, 192)
#: Input and output channels.
INPUTS, OUTPUTS = 2, 4


def _need_training_extra():
    try:
        import jax
        import jax.numpy as jnp
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise ImportError(
            "training the shape prior needs the training extra: pip install 'shadeform[train]'"
        ) from error
    return jax, jnp


def layers(widths=WIDTHS) -> list[tuple[str, int, int]]:
    """The convolutions in order: ``(name, in_channels, out_channels)``, all 3x3."""
    out = []
    cin = INPUTS
    for level, width in enumerate(widths):
        out += [(f"down{level}a", cin, width), (f"down{level}b", width, width)]
        cin = width
    for level in range(len(widths) - 2, -1, -1):
        width = widths[level]
        out += [(f"up{level}a", cin + width, width), (f"up{level}b", width, width)]
        cin = width
    out.append(("head", cin, OUTPUTS))
    return out


def init(seed: int, *, widths=WIDTHS) -> dict[str, np.ndarray]:
    """He-initialised weights: ``{name + '.w': (3, 3, in, out), name + '.b': (out,)}`` float32."""
    rng = np.random.default_rng(seed)
    params = {}
    for name, cin, cout in layers(widths):
        scale = np.sqrt(2.0 / (9 * cin)) if name != "head" else 1e-2
        params[name + ".w"] = (rng.standard_normal((3, 3, cin, cout)) * scale).astype(np.float32)
        params[name + ".b"] = np.zeros(cout, np.float32)
    # start the normal at +z and the error scale at about 0.3 rad
    params["head.b"][2] = 1.0
    params["head.b"][3] = np.log(0.3)
    return params


def apply(params, x):
    """The network in JAX: ``x`` (N, S, S, 2) NHWC -> (N, S, S, 4)."""
    jax, jnp = _need_training_extra()

    def conv(name, h, relu=True):
        h = jax.lax.conv_general_dilated(
            h, params[name + ".w"], (1, 1), "SAME", dimension_numbers=("NHWC", "HWIO", "NHWC")
        )
        h = h + params[name + ".b"]
        return jax.nn.relu(h) if relu else h

    levels = sum(1 for key in params if key.startswith("down") and key.endswith("a.w"))
    skips = []
    h = x
    for level in range(levels):
        h = conv(f"down{level}b", conv(f"down{level}a", h))
        if level < levels - 1:
            skips.append(h)
            n, height, width, c = h.shape
            h = h.reshape(n, height // 2, 2, width // 2, 2, c).mean(axis=(2, 4))
    for level in range(levels - 2, -1, -1):
        h = jnp.repeat(jnp.repeat(h, 2, axis=1), 2, axis=2)
        h = jnp.concatenate([h, skips[level]], axis=-1)
        h = conv(f"up{level}b", conv(f"up{level}a", h))
    return conv("head", h, relu=False)


def to_onnx(params: dict[str, np.ndarray], *, size: int = SIZE):
    """The same network as an ONNX model (opset 17), NCHW: input ``x`` (N, 2, size, size) -> ``y``
    (N, 4, size, size)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    nodes, weights = [], []

    def conv(name, h, relu=True):
        w = np.ascontiguousarray(np.asarray(params[name + ".w"], np.float32).transpose(3, 2, 0, 1))
        weights.append(numpy_helper.from_array(w, name + ".w"))
        weights.append(numpy_helper.from_array(np.asarray(params[name + ".b"], np.float32), name + ".b"))
        out = name + ".conv"
        nodes.append(helper.make_node("Conv", [h, name + ".w", name + ".b"], [out], pads=[1, 1, 1, 1]))
        if relu:
            nodes.append(helper.make_node("Relu", [out], [name]))
            return name
        return out

    weights.append(numpy_helper.from_array(np.array([1, 1, 2, 2], np.float32), "scales"))
    levels = sum(1 for key in params if key.startswith("down") and key.endswith("a.w"))
    skips, h = [], "x"
    for level in range(levels):
        h = conv(f"down{level}b", conv(f"down{level}a", h))
        if level < levels - 1:
            skips.append(h)
            nodes.append(
                helper.make_node("AveragePool", [h], [f"pool{level}"], kernel_shape=[2, 2], strides=[2, 2])
            )
            h = f"pool{level}"
    for level in range(levels - 2, -1, -1):
        nodes.append(
            helper.make_node(
                "Resize",
                [h, "", "scales"],
                [f"grow{level}"],
                mode="nearest",
                coordinate_transformation_mode="asymmetric",
                nearest_mode="floor",
            )
        )
        nodes.append(helper.make_node("Concat", [f"grow{level}", skips[level]], [f"cat{level}"], axis=1))
        h = conv(f"up{level}b", conv(f"up{level}a", f"cat{level}"))
    nodes.append(helper.make_node("Identity", [conv("head", h, relu=False)], ["y"]))
    graph = helper.make_graph(
        nodes,
        "shadeform-prior",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["N", INPUTS, size, size])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["N", OUTPUTS, size, size])],
        initializer=weights,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="shadeform")
    model.ir_version = 8  # readable by every onnxruntime of the last years
    onnx.checker.check_model(model)
    return model


def loss(params, x, target, weight):
    """Mean Laplace negative log-likelihood of the chord to the true normal.

    Parameters
    ----------
    x : (N, S, S, 2)
    target : (N, S, S, 3)
        True unit normals (anything where ``weight`` is 0).
    weight : (N, S, S)
        1 on the object's pixels inside the given mask, 0 elsewhere.
    """
    _, jnp = _need_training_extra()
    y = apply(params, x)
    n = y[..., :3] / jnp.sqrt(jnp.sum(y[..., :3] ** 2, axis=-1, keepdims=True) + 1e-6)
    log_s = jnp.clip(y[..., 3], -6.0, 2.0)
    chord = jnp.sqrt(jnp.sum((n - target) ** 2, axis=-1) + 1e-8)
    nll = chord * jnp.exp(-log_s) + log_s
    return jnp.sum(nll * weight) / jnp.maximum(jnp.sum(weight), 1.0)

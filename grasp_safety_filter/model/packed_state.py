"""A GraspState whose terms live in one read-only buffer, each handed out when first read."""

from __future__ import annotations

from collections.abc import Callable
import dataclasses
from functools import cached_property, partial
from typing import Any

import numpy as np

from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.contact_surfaces import CompiledContacts
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.hand import HandModel
from grasp_safety_filter.model.packed_terms import packed_fields, PackedLayout
from grasp_safety_filter.model.rigid_object import RigidObject

#: GraspState's affine terms and the packed ``[matrix | offset]`` each is a view of.
_AFFINE = {
    'contact_force': 'contact_force_augmented',
    'joint_acceleration': 'joint_acceleration_augmented',
    'object_acceleration': 'object_acceleration_augmented',
    'xi_cf_ddot': 'xi_cf_ddot_augmented',
    'xi_co_ddot': 'xi_co_ddot_augmented',
}

#: GraspState fields :meth:`PackedGraspState.of` sets (not in the buffer).
_SET_BY_OF = ('t', 'w_e')


class _View:
    """A field of :class:`PackedGraspState`: made from the buffer on first read, then kept.

    A non-data descriptor: once the instance holds the field, Python reads it from there
    and never calls this again.
    """

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, state: PackedGraspState | None, owner: type | None = None) -> Any:
        if state is None:
            return self
        fields = state.__dict__
        if '_layout' not in fields:  # a copy with every field given (dataclasses.replace)
            raise AttributeError(self.name)
        value = state._make(self.name)
        fields[self.name] = value
        return value


class PackedGraspState(GraspState):
    """A :class:`GraspState` whose fields are views of one read-only buffer.

    The buffer is :func:`~grasp_safety_filter.model.packed_terms.sphere_on_plane_terms`'s
    (or ``sphere_on_sphere_terms``'), made read-only. Each field is a view of the buffer,
    made when it is first read and kept; a tick's state is thus built with no array per
    term, and a consumer pays only for the fields it reads. Build with :meth:`of`;
    ``dataclasses.replace`` gives a copy with every field set.
    """

    @property
    def packed_terms(self) -> tuple[np.ndarray, PackedLayout] | None:
        """The buffer and its layout (None for a copy whose fields were given)."""
        fields = self.__dict__
        return (fields['_buffer'], fields['_layout']) if '_layout' in fields else None

    @property
    def n_contacts(self) -> int:
        """Number of contacts n."""
        layout = self.__dict__.get('_layout')
        return layout.n_contacts if layout is not None else self.xi_cf.shape[0]

    @property
    def n_joints(self) -> int:
        """Number of joints m."""
        layout = self.__dict__.get('_layout')
        return layout.n_joints if layout is not None else self.q.shape[0]

    @classmethod
    def of(
        cls,
        t: float,
        buffer: np.ndarray,
        layout: PackedLayout,
        w_e: np.ndarray,
        contacts: CompiledContacts,
    ) -> PackedGraspState:
        """Wrap a filled buffer (made read-only here) as the state at time ``t``, s.

        Args:
            t: Time stamp, s.
            buffer: The terms, laid out as ``layout`` says.
            layout: Where each term lies.
            w_e: The external wrench on the object, (6,), read-only.
            contacts: The contact surfaces (for :attr:`GraspState.xi_co_rate_terms`).
        """
        buffer.setflags(write=False)
        state = object.__new__(cls)
        fields = state.__dict__
        fields['t'] = t
        fields['w_e'] = w_e
        fields['_buffer'] = buffer
        fields['_layout'] = layout
        fields['_contacts'] = contacts
        return state

    @cached_property
    def xi_co_ddot(self) -> AffineMap:
        """:attr:`GraspState.xi_co_ddot`: a view of the buffer's ``xi_co_ddot_augmented``.

        On a copy whose fields were given, formed as :class:`GraspState` forms it.
        """
        if '_layout' not in self.__dict__:
            return GraspState.xi_co_ddot.func(self)
        return self._make('xi_co_ddot')

    def _make(self, name: str) -> Any:
        places = self._layout.places
        if name in places:
            start, stop, shape = places[name]
            return self._buffer[start:stop].reshape(shape)
        augmented_name = _AFFINE.get(name)
        if augmented_name is not None:
            augmented = getattr(self, augmented_name)
            m = self._layout.n_joints
            return AffineMap(augmented[:, :m], augmented[:, m])
        if name == 'xi_co_rate_terms':
            return self._rate_terms()
        raise AttributeError(name)

    def _rate_terms(self) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
        return partial(
            self._contacts.object_rate_terms,
            self.xi_cf,
            self.xi_co,
            self.psi,
            self.xi_cf_dot,
            self.xi_co_dot,
            self.psi_dot,
            self.sliding_velocity,
        )


def _install_views(cls: type[PackedGraspState]) -> None:
    """Give ``cls`` a :class:`_View` per buffer term, per affine map and for the rate terms.

    The names come from :func:`~grasp_safety_filter.model.packed_terms.packed_fields`
    (which does not depend on n and m), so the buffer's terms are listed once; every
    GraspState field not in the buffer must be set by :meth:`PackedGraspState.of`.
    """
    # xi_co_ddot, a GraspState property, keeps its own (the class's) for copies.
    affine = [name for name in _AFFINE if name not in cls.__dict__]
    names = [name for name, _ in packed_fields(1, 1)] + [*affine, 'xi_co_rate_terms']
    unset = {field.name for field in dataclasses.fields(GraspState)} - set(names) - set(_SET_BY_OF)
    if unset:
        raise TypeError(f'PackedGraspState: no view or value for {sorted(unset)}')
    for name in names:
        view = _View()
        view.__set_name__(cls, name)
        setattr(cls, name, view)


_install_views(PackedGraspState)


def packed_state(
    hand: HandModel,
    rigid_object: RigidObject,
    contacts: CompiledContacts,
    layout: PackedLayout,
    sample: tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> PackedGraspState:
    """Return every model term of one instant, computed in one compiled pass.

    The contacts' ``terms_kernel`` (:func:`~grasp_safety_filter.model.packed_terms.
    sphere_on_plane_terms` for spherical fingertips on flat faces, ``sphere_on_sphere_terms``
    on a sphere object) computes every term from Pinocchio's terms and the object's mass
    matrices into one buffer.

    Args:
        hand: The hand.
        rigid_object: The object.
        contacts: The contact surfaces (:func:`~grasp_safety_filter.model.contact_surfaces.
            compiled_contacts`).
        layout: The buffer's layout for these contacts and joints.
        sample: ``(t, q, dq, p_object_in_palm, R_object_to_palm, twist_object)``.

    Terms that overflow (a huge but finite input) or inputs that are not finite give
    non-finite terms (NaN from the solve of ``B_ho`` on), which consumers refuse.

    Raises:
        numpy.linalg.LinAlgError: ``B_ho`` is singular.
        ValueError: A fingertip centre is a sphere object's centre, or an input's shape is
            not the model's: q and dq (m,), ``p_object_in_palm`` (3,), ``R_object_to_palm``
            (3, 3), ``twist_object`` (6,).
    """
    t, q, dq, p_object_in_palm, R_object_to_palm, twist_object = sample
    q, dq, p_o, R_o, twist_o = map(
        _kernel_input, (q, dq, p_object_in_palm, R_object_to_palm, twist_object)
    )
    m = layout.n_joints
    if (
        q.shape != (m,)
        or dq.shape != (m,)
        or p_o.shape != (3,)
        or R_o.shape != (3, 3)
        or twist_o.shape != (6,)
    ):
        # The compiled pass writes each input into the buffer without bounds checks.
        _raise_shape_error(
            m, q=q, dq=dq, p_object_in_palm=p_o, R_object_to_palm=R_o, twist_object=twist_o
        )
    raw = hand.raw_terms(q, dq)
    w_e = rigid_object.external_wrench()
    buffer = np.empty(layout.size)
    contacts.terms_kernel(
        buffer, raw, hand.fingertip_frames, hand.pinocchio_index, hand.branches,
        q, dq, p_o, R_o, twist_o,
        rigid_object.mass_matrices_in_body, rigid_object.isotropic, w_e,
        contacts.surface_arrays, layout.torsion, layout.torsional_compliance,
    )
    return PackedGraspState.of(float(t), buffer, layout, w_e, contacts)


def _kernel_input(value: Any) -> np.ndarray:
    """Return ``value`` as a read-only C-ordered float64 array.

    Numba specialises a kernel on its arrays' layout and write flag: with every caller's
    inputs alike (the simulator's read-only state, a node's parsed messages, a bag's rows),
    one compiled pass serves them all, instead of one compiled (seconds) per kind of caller.
    """
    array = np.ascontiguousarray(value, dtype=np.float64)
    if array.flags.writeable:
        array = array.view()
        array.flags.writeable = False
    return array


def _raise_shape_error(m: int, **inputs: np.ndarray) -> None:
    """Raise ValueError naming each input whose shape is not the model's."""
    expected = {
        'q': (m,),
        'dq': (m,),
        'p_object_in_palm': (3,),
        'R_object_to_palm': (3, 3),
        'twist_object': (6,),
    }
    wrong = [
        f'{name}: expected shape {expected[name]}, got {array.shape}'
        for name, array in inputs.items()
        if array.shape != expected[name]
    ]
    raise ValueError('grasp state: ' + '; '.join(wrong))

"""Review workshops: workshop, workshop_plot (static PNG, render parameters, SHA-256),
workshop_reviewer (personal link as SHA-256, order seed, sequence) and workshop_answer
(one row per place of a reviewer's sequence).

Revision ID: 0003_workshops
Revises: 0004_calibration_sections
"""
from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003_workshops"
down_revision: str | Sequence[str] | None = "0004_calibration_sections"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table('workshop',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('name', sa.String(length=200), nullable=False),
    sa.Column('campaign_id', sa.Integer(), nullable=False),
    sa.Column('status', sa.String(length=20), nullable=False),
    sa.Column('blind', sa.Boolean(), nullable=False),
    sa.Column('repeat_share', sa.Float(), nullable=False),
    sa.Column('auto_share', sa.Float(), nullable=False),
    sa.Column('settings', sa.JSON(), nullable=False),
    sa.Column('scales', sa.JSON(), nullable=False),
    sa.Column('created_by', sa.Integer(), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['campaign_id'], ['campaign.id'], name=op.f('fk_workshop_campaign_id_campaign'), ondelete='RESTRICT'),
    sa.ForeignKeyConstraint(['created_by'], ['app_user.id'], name=op.f('fk_workshop_created_by_app_user'), ondelete='SET NULL'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_workshop')),
    sa.UniqueConstraint('name', name=op.f('uq_workshop_name'))
    )
    op.create_index(op.f('ix_workshop_campaign_id'), 'workshop', ['campaign_id'], unique=False)
    op.create_table('workshop_plot',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('workshop_id', sa.Integer(), nullable=False),
    sa.Column('kind', sa.String(length=40), nullable=False),
    sa.Column('section', sa.String(length=100), nullable=False),
    sa.Column('configuration', sa.String(length=200), nullable=False),
    sa.Column('channel', sa.String(length=100), nullable=False),
    sa.Column('scaling', sa.String(length=10), nullable=False),
    sa.Column('twin_id', sa.Integer(), nullable=True),
    sa.Column('deviation', sa.Float(), nullable=True),
    sa.Column('sg_c', sa.Float(), nullable=True),
    sa.Column('render', sa.JSON(), nullable=False),
    sa.Column('image_sha256', sa.String(length=64), nullable=False),
    sa.Column('image', sa.LargeBinary(), nullable=False),
    sa.ForeignKeyConstraint(['twin_id'], ['workshop_plot.id'], name=op.f('fk_workshop_plot_twin_id_workshop_plot'), ondelete='SET NULL'),
    sa.ForeignKeyConstraint(['workshop_id'], ['workshop.id'], name=op.f('fk_workshop_plot_workshop_id_workshop'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_workshop_plot'))
    )
    op.create_index('ix_workshop_plot_workshop', 'workshop_plot', ['workshop_id', 'id'], unique=False)
    op.create_table('workshop_reviewer',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('workshop_id', sa.Integer(), nullable=False),
    sa.Column('user_id', sa.Integer(), nullable=False),
    sa.Column('seed', sa.Integer(), nullable=False),
    sa.Column('sequence', sa.JSON(), nullable=False),
    sa.Column('token_sha256', sa.String(length=64), nullable=True),
    sa.Column('invited_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('finished_at', sa.DateTime(timezone=True), nullable=True),
    sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['user_id'], ['app_user.id'], name=op.f('fk_workshop_reviewer_user_id_app_user'), ondelete='RESTRICT'),
    sa.ForeignKeyConstraint(['workshop_id'], ['workshop.id'], name=op.f('fk_workshop_reviewer_workshop_id_workshop'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_workshop_reviewer')),
    sa.UniqueConstraint('token_sha256', name=op.f('uq_workshop_reviewer_token_sha256')),
    sa.UniqueConstraint('workshop_id', 'user_id', name=op.f('uq_workshop_reviewer_workshop_id'))
    )
    op.create_index(op.f('ix_workshop_reviewer_user_id'), 'workshop_reviewer', ['user_id'], unique=False)
    op.create_table('workshop_answer',
    sa.Column('id', sa.Integer(), nullable=False),
    sa.Column('reviewer_id', sa.Integer(), nullable=False),
    sa.Column('plot_id', sa.Integer(), nullable=False),
    sa.Column('position', sa.Integer(), nullable=False),
    sa.Column('repeat', sa.Boolean(), nullable=False),
    sa.Column('answer', sa.Boolean(), nullable=False),
    sa.Column('comment', sa.Text(), nullable=False),
    sa.Column('seconds', sa.Float(), nullable=False),
    sa.Column('changes', sa.Integer(), nullable=False),
    sa.Column('submission', sa.String(length=64), nullable=False),
    sa.Column('source', sa.String(length=10), nullable=False),
    sa.Column('answered_at', sa.DateTime(timezone=True), nullable=False),
    sa.Column('updated_at', sa.DateTime(timezone=True), nullable=False),
    sa.ForeignKeyConstraint(['plot_id'], ['workshop_plot.id'], name=op.f('fk_workshop_answer_plot_id_workshop_plot'), ondelete='CASCADE'),
    sa.ForeignKeyConstraint(['reviewer_id'], ['workshop_reviewer.id'], name=op.f('fk_workshop_answer_reviewer_id_workshop_reviewer'), ondelete='CASCADE'),
    sa.PrimaryKeyConstraint('id', name=op.f('pk_workshop_answer')),
    sa.UniqueConstraint('reviewer_id', 'position', name=op.f('uq_workshop_answer_reviewer_id'))
    )
    op.create_index('ix_workshop_answer_plot', 'workshop_answer', ['plot_id'], unique=False)


def downgrade() -> None:
    op.drop_index('ix_workshop_answer_plot', table_name='workshop_answer')
    op.drop_table('workshop_answer')
    op.drop_index(op.f('ix_workshop_reviewer_user_id'), table_name='workshop_reviewer')
    op.drop_table('workshop_reviewer')
    op.drop_index('ix_workshop_plot_workshop', table_name='workshop_plot')
    op.drop_table('workshop_plot')
    op.drop_index(op.f('ix_workshop_campaign_id'), table_name='workshop')
    op.drop_table('workshop')
